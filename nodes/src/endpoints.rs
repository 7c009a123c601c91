//! Typed publishers and subscriptions on tokio (made by [`crate::ros::RosNode`]): a publish names its
//! topic and type when it fails; a subscription survives payloads that do not decode.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{anyhow, bail};
use equiarm_msgs::RosMessage;
use log::warn;
use ros2_client::{MessageInfo, ReadError};

use crate::ros::RosNode;

/// Counts of dropped payloads, shared by the subscriptions of one node.
#[derive(Default)]
pub(crate) struct BadInputLog {
    counts: Mutex<HashMap<String, u64>>,
}

impl BadInputLog {
    /// Counts one bad payload on `topic`; returns the new count (1 means: log it).
    pub(crate) fn record(&self, topic: &str) -> u64 {
        let mut c = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        let n = c.entry(topic.to_string()).or_insert(0);
        *n += 1;
        *n
    }

    pub(crate) fn counts(&self) -> HashMap<String, u64> {
        self.counts.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

/// A typed publisher; [`Publisher::publish`] never blocks the runtime for long (reliable writers wait
/// at most 100 ms for window space, then report an error).
pub struct Publisher<M: RosMessage> {
    pub(crate) inner: ros2_client::Publisher<M>,
    pub(crate) topic: String,
}

impl<M: RosMessage> Publisher<M> {
    /// Publishes `msg`; the error names the topic and type.
    pub async fn publish(&self, msg: M) -> anyhow::Result<()> {
        self.inner
            .async_publish(msg)
            .await
            .map_err(|e| anyhow!("publishing {} on '{}': {e:?}", M::TYPE_NAME, self.topic))
    }

    /// The topic name as given at creation.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Subscriptions matched so far (0 until the first match).
    pub fn subscription_count(&self, node: &RosNode) -> usize {
        self.inner.get_subscription_count(&node.node)
    }
}

/// A typed subscription that survives bad input.
pub struct Subscriber<M: RosMessage> {
    pub(crate) inner: ros2_client::Subscription<M>,
    pub(crate) topic: String,
    pub(crate) log: Arc<BadInputLog>,
}

impl<M: RosMessage> Subscriber<M> {
    /// The next message that decodes, with its metadata. A payload that does not decode as `M` is
    /// counted, logged (the first time per topic, with topic and type), and skipped; reading goes on.
    /// Returns an error only if the middleware itself fails (reader closed).
    pub async fn recv(&self) -> anyhow::Result<(M, MessageInfo)> {
        loop {
            match self.inner.async_take().await {
                Ok(v) => return Ok(v),
                Err(ReadError::Deserialization { reason }) => {
                    if self.log.record(&self.topic) == 1 {
                        warn!(
                            "dropping a payload on '{}' that does not decode as {}: {reason} \
                             (further ones on this topic are only counted)",
                            self.topic,
                            M::TYPE_NAME
                        );
                    }
                }
                Err(ReadError::Closed) => bail!("subscription to '{}' ({}) closed", self.topic, M::TYPE_NAME),
                Err(e) => {
                    warn!("reading '{}' ({}): {e}; retrying", self.topic, M::TYPE_NAME);
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            }
        }
    }

    /// As [`Self::recv`] but gives up after `timeout` (`Ok(None)`).
    pub async fn recv_timeout(&self, timeout: Duration) -> anyhow::Result<Option<(M, MessageInfo)>> {
        match tokio::time::timeout(timeout, self.recv()).await {
            Ok(r) => r.map(Some),
            Err(_) => Ok(None),
        }
    }

    /// The topic name as given at creation.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Publishers matched so far, as this node has discovered them (the remote side may not have
    /// matched this subscription yet).
    pub fn publisher_count(&self, node: &RosNode) -> usize {
        self.inner.get_publisher_count(&node.node)
    }

    /// Payloads dropped on this topic so far.
    pub fn bad_input_count(&self) -> u64 {
        self.log.counts().get(&self.topic).copied().unwrap_or(0)
    }
}
