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

/// A message serialized as itself, followed with `pad` by up to three zero bytes so that the
/// serialized payload (4-byte encapsulation header and CDR body) is a multiple of 4 bytes long, as
/// RTPS allows (DDS-RTPS 2.5 §10.2: a payload may end in up to 3 padding bytes; CDR readers stop at
/// the end of the type). Secured nodes need it: RustDDS 0.15.1 encrypts a payload and then pads the
/// DATA submessage to 4 bytes, but when decrypting it reads the MAC from the end of that padded
/// payload, so a sample whose length is not a multiple of 4 never decrypts (docs/security.md).
pub(crate) struct Padded<M> {
    pub(crate) msg: M,
    pub(crate) pad: bool,
}

impl<M: serde::Serialize> serde::Serialize for Padded<M> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{Error as _, SerializeTuple};
        if !self.pad {
            return self.msg.serialize(s);
        }
        let mut counter = ByteCount(0);
        cdr_encoding::to_writer::<M, byteorder::LittleEndian, _>(&mut counter, &self.msg)
            .map_err(|e| S::Error::custom(format!("measuring a sample: {e}")))?;
        let pad = (4 - counter.0 % 4) % 4;
        let mut t = s.serialize_tuple(1 + pad)?;
        t.serialize_element(&self.msg)?;
        for _ in 0..pad {
            t.serialize_element(&0u8)?;
        }
        t.end()
    }
}

/// Errors name the topic and type, not the sample (which may be megabytes).
impl<M> std::fmt::Debug for Padded<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("(the sample)")
    }
}

/// An `io::Write` that only counts.
struct ByteCount(usize);

impl std::io::Write for ByteCount {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len();
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A typed publisher; [`Publisher::publish`] never blocks the runtime for long (reliable writers wait
/// at most 100 ms for window space, then report an error).
pub struct Publisher<M: RosMessage> {
    pub(crate) inner: ros2_client::Publisher<Padded<M>>,
    pub(crate) topic: String,
    /// Pad each sample's CDR to a multiple of 4 bytes (on a secured node; see [`Padded`]).
    pub(crate) pad: bool,
}

impl<M: RosMessage> Publisher<M> {
    /// Publishes `msg`; the error names the topic and type.
    pub async fn publish(&self, msg: M) -> anyhow::Result<()> {
        self.inner
            .async_publish(Padded { msg, pad: self.pad })
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

    /// Returns once `n` subscriptions have matched (at once for `n` = 0), saying every 5 s how many
    /// have. A reliable, volatile writer keeps (and repairs) only what it writes after a reader has
    /// matched; under DDS Security that match comes seconds after the participants meet.
    pub async fn wait_for_subscriptions(&self, node: &RosNode, n: usize) {
        if n == 0 {
            return;
        }
        // the first match through the node's graph events (counting before it logs an error)
        let first = self.inner.wait_for_subscription(&node.node);
        tokio::pin!(first);
        let mut said = tokio::time::interval_at(tokio::time::Instant::now() + SAY_EVERY, SAY_EVERY);
        loop {
            tokio::select! {
                () = &mut first => break,
                _ = said.tick() => log::info!("{}: waiting for {n} subscriber(s), none matched yet", self.topic),
            }
        }
        loop {
            let have = self.subscription_count(node);
            if have >= n {
                log::info!("{}: {have} subscriber(s) matched", self.topic);
                return;
            }
            tokio::select! {
                () = tokio::time::sleep(Duration::from_millis(50)) => {}
                _ = said.tick() => log::info!("{}: waiting for {n} subscriber(s), {have} matched", self.topic),
            }
        }
    }
}

/// How often [`Publisher::wait_for_subscriptions`] says it is still waiting.
const SAY_EVERY: Duration = Duration::from_secs(5);

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

#[cfg(test)]
mod tests {
    use super::*;
    use byteorder::LittleEndian;
    use equiarm_msgs::msg::{EpisodeResult, GripperCommand};

    /// Padded payloads (4-byte header + body) are a multiple of 4 long and read back as the message;
    /// unpadded ones are exactly the message's CDR.
    #[test]
    fn padded_samples_are_a_multiple_of_four_bytes_and_read_back_unchanged() {
        let cmd = GripperCommand { obs_seq: 3, ..Default::default() };
        let plain = cdr_encoding::to_vec::<_, LittleEndian>(&cmd).unwrap();
        assert_eq!(cdr_encoding::to_vec::<_, LittleEndian>(&Padded { msg: cmd.clone(), pad: false }).unwrap(), plain);
        for env in ["", "a", "ab", "abc", "abcd"] {
            let ep = EpisodeResult { env: env.to_string(), ..Default::default() };
            let bytes = cdr_encoding::to_vec::<_, LittleEndian>(&Padded { msg: ep.clone(), pad: true }).unwrap();
            assert_eq!((4 + bytes.len()) % 4, 0, "env '{env}': {} bytes", bytes.len());
            let (back, _) = cdr_encoding::from_bytes::<EpisodeResult, LittleEndian>(&bytes).unwrap();
            assert_eq!(back, ep);
        }
    }
}
