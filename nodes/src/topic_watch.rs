//! The recorder's watch over each recorded topic's publishers: it says when a topic that had some has
//! none left (a publisher ended, or DDS lost it) and when one is back.

use log::{info, warn};

use crate::ros::RosNode;

/// A recorded topic's publisher count, as discovery sees it.
pub struct Watch {
    /// The topic.
    pub name: String,
    /// Its publisher count now.
    pub count: Box<dyn Fn(&RosNode) -> usize + Send>,
    /// Publishers were seen at some point.
    pub had: bool,
    /// None are left now (and a warning said so).
    pub lost: bool,
}

impl Watch {
    /// Compares the publisher count with the last one and logs a loss or a return.
    pub fn check(&mut self, node: &RosNode) {
        let n = (self.count)(node);
        if n > 0 {
            if self.lost {
                info!("{}: a publisher is back ({n} now); recording it again", self.name);
            }
            (self.had, self.lost) = (true, false);
        } else if self.had && !self.lost {
            self.lost = true;
            warn!(
                "{}: every publisher is gone (it ended, or DDS lost it); the bag has nothing of this topic until one is back",
                self.name
            );
        }
    }
}
