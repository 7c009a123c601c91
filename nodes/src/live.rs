//! The recorder's live view for Foxglove without a ROS installation (`equiarm record --foxglove
//! [HOST:]PORT`): a WebSocket server speaking Foxglove's protocol (`foxglove.websocket.v1`, the
//! `foxglove` crate's pure-Rust server) that re-publishes every message the recorder writes, on a
//! channel per topic with the bag's schema (`ros2msg`, the full message definition) and message
//! encoding (`cdr`): a client gets the same bytes the bag records, with the recorder's receive time.
//! It listens on loopback unless another address is given.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;

use anyhow::Context as _;
use equiarm_bag::{TopicId, TopicInfo};
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer, WebSocketServerHandle};

/// Parses `PORT` (loopback) or `HOST:PORT` (an IP address; `0.0.0.0` listens on every interface).
pub fn address(s: &str) -> Result<SocketAddr, String> {
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
    }
    s.parse::<SocketAddr>().map_err(|_| {
        format!("'{s}': expected PORT (on loopback) or HOST:PORT with HOST an IP address, e.g. 127.0.0.1:8765")
    })
}

/// The running server and the channel of each recorded topic.
pub struct Live {
    ctx: Arc<Context>,
    server: WebSocketServerHandle,
    channels: HashMap<TopicId, Arc<RawChannel>>,
}

impl Live {
    /// Starts the server on `addr` (port 0: any free port).
    pub async fn start(addr: SocketAddr) -> anyhow::Result<Self> {
        let ctx = Context::new();
        let server = WebSocketServer::new()
            .name("equiarm record")
            .bind(addr.ip().to_string(), addr.port())
            .context(&ctx)
            .start()
            .await
            .with_context(|| format!("starting the Foxglove WebSocket server on {addr}"))?;
        log::info!("Foxglove live view on ws://{}:{}", addr.ip(), server.port());
        Ok(Self { ctx, server, channels: HashMap::new() })
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.server.port()
    }

    /// Advertises the recorded topic `info` (added to the bag as `topic`).
    pub fn add(&mut self, topic: TopicId, info: &TopicInfo) -> anyhow::Result<()> {
        let schema = Schema::new(info.type_name.clone(), info.schema_encoding.clone(), info.schema.clone());
        let channel = ChannelBuilder::new(info.name.clone())
            .message_encoding("cdr")
            .schema(schema)
            .context(&self.ctx)
            .build_raw()
            .with_context(|| format!("advertising {} to Foxglove", info.name))?;
        self.channels.insert(topic, channel);
        Ok(())
    }

    /// Sends a recorded message to the clients subscribed to its topic.
    pub fn log(&self, topic: TopicId, log_time: u64, data: &[u8]) {
        if let Some(c) = self.channels.get(&topic) {
            c.log_with_meta(data, PartialMetadata { log_time: Some(log_time) });
        }
    }
}
