//! The sim's camera topics (`camera/color/image_raw`, `camera/depth/image_raw`,
//! `camera/camera_info`, best effort): each Observation's frame under its stamp. A topic is sent
//! only while something subscribes to it (the images are decoded from the Observation only then);
//! one whose subscriber matched after the frame was published (a recorder starting beside the sims
//! misses an env's first frame otherwise) gets it while the sim waits for the frame's command
//! ([`CameraPublishers::catch_up`]), so each subscriber sees each frame once.

use std::time::Duration;

use equiarm_msgs::msg::Observation;
use equiarm_msgs::sensor_msgs::{CameraInfo, Image};
use equiarm_msgs::std_msgs::Header;
use equiarm_sim::Env;
use equiarm_train::stepper::CAMERA_FRAME;

use crate::ros::{Publisher, RosNode, qos};

/// How often the sim looks for late camera subscribers while a frame waits for its command.
pub const CATCH_UP_POLL: Duration = Duration::from_millis(50);

/// The camera publishers and which of them the current frame has not reached.
pub struct CameraPublishers {
    color: Publisher<Image>,
    depth: Publisher<Image>,
    info: Publisher<CameraInfo>,
    camera_info: CameraInfo,
    /// Colour, depth, info: the current frame was published while nobody subscribed.
    unsent: [bool; 3],
}

impl CameraPublishers {
    /// The three publishers under the node's namespace, with the camera's intrinsics of `env`.
    pub fn new(node: &mut RosNode, env: &Env) -> anyhow::Result<Self> {
        let ci = env.camera().camera_info();
        let camera_info = CameraInfo {
            height: ci.height,
            width: ci.width,
            distortion_model: ci.distortion_model.to_string(),
            d: ci.d.to_vec(),
            k: ci.k,
            r: ci.r,
            p: ci.p,
            ..Default::default()
        };
        Ok(Self {
            color: node.publisher("camera/color/image_raw", qos::sensor_data())?,
            depth: node.publisher("camera/depth/image_raw", qos::sensor_data())?,
            info: node.publisher("camera/camera_info", qos::sensor_data())?,
            camera_info,
            unsent: [false; 3],
        })
    }

    /// Publishes the frame of `obs` (its stamp, the camera's frame id; depth at the Observation's
    /// precision) on each topic someone subscribes to, and notes the others.
    pub async fn publish(&mut self, node: &RosNode, obs: &Observation) -> anyhow::Result<()> {
        self.unsent = [true; 3];
        self.catch_up(node, obs).await
    }

    /// Whether a topic has not had the current frame.
    pub fn pending(&self) -> bool {
        self.unsent.iter().any(|&u| u)
    }

    /// Publishes the current frame `obs` on the topics that had not had it and now have a subscriber.
    pub async fn catch_up(&mut self, node: &RosNode, obs: &Observation) -> anyhow::Result<()> {
        let header = Header::new(obs.header.stamp.clone(), CAMERA_FRAME);
        if self.unsent[0] && self.color.subscription_count(node) > 0 {
            self.color.publish(obs.color_image(header.clone())?).await?;
            self.unsent[0] = false;
        }
        if self.unsent[1] && self.depth.subscription_count(node) > 0 {
            self.depth.publish(obs.depth_image(header.clone())?).await?;
            self.unsent[1] = false;
        }
        if self.unsent[2] && self.info.subscription_count(node) > 0 {
            self.info.publish(CameraInfo { header, ..self.camera_info.clone() }).await?;
            self.unsent[2] = false;
        }
        Ok(())
    }
}
