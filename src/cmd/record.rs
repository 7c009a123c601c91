//! `equiarm record`: the recorder node.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::bail;
use equiarm_nodes::ros::RosOptions;

/// `equiarm record`'s arguments.
#[derive(clap::Args)]
pub struct RecordArgs {
    /// Bag directory to create (must not exist, or be empty).
    #[arg(short, long)]
    output: std::path::PathBuf,
    /// Topics to record, as TOPIC:TYPE (e.g. /env0/observation:equiarm_msgs/msg/Observation).
    topics: Vec<String>,
    /// Also record every topic of a known type that appears on the graph.
    #[arg(short, long)]
    all: bool,
    /// With --all: how often to look for new topics, in ms (as rosbag2's --polling-interval).
    #[arg(long, default_value_t = 100, value_parser = equiarm_nodes::cli_values::millis)]
    polling_interval_ms: u64,
    /// Chunk compression.
    #[arg(long, value_enum, default_value = "zstd")]
    compression: CompressionArg,
    /// Start a new file after this many MB of messages.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    split_size_mb: Option<u64>,
    /// Start a new file after this many seconds.
    #[arg(long, value_parser = equiarm_nodes::cli_values::whole_seconds)]
    split_duration_s: Option<u64>,
    /// Flush interval in ms: a killed recorder loses at most about this much.
    #[arg(long, default_value_t = 250, value_parser = equiarm_nodes::cli_values::millis)]
    flush_ms: u64,
    /// Stop after this many seconds (default: until Ctrl-C / SIGTERM).
    #[arg(long, value_parser = equiarm_nodes::cli_values::seconds)]
    duration_s: Option<f64>,
    /// No live status line.
    #[arg(long, short)]
    quiet: bool,
    /// Also serve what is recorded to Foxglove (its WebSocket protocol; no ROS install needed) on
    /// PORT on loopback, or on HOST:PORT (e.g. 0.0.0.0:8765 for every interface).
    #[arg(long, value_name = "[HOST:]PORT", value_parser = equiarm_nodes::live::address)]
    foxglove: Option<std::net::SocketAddr>,
}

/// Chunk compression of the bag.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CompressionArg {
    None,
    Lz4,
    Zstd,
}

impl From<CompressionArg> for equiarm_bag::Compression {
    fn from(c: CompressionArg) -> Self {
        match c {
            CompressionArg::None => equiarm_bag::Compression::None,
            CompressionArg::Lz4 => equiarm_bag::Compression::Lz4,
            CompressionArg::Zstd => equiarm_bag::Compression::Zstd,
        }
    }
}

/// Runs the recorder until Ctrl-C, SIGTERM or `--duration-s`.
pub fn run(a: RecordArgs) -> anyhow::Result<ExitCode> {
    let mut topics = Vec::new();
    for t in &a.topics {
        let Some((name, ty)) = t.split_once(':') else {
            bail!("topic '{t}' must be given as TOPIC:TYPE, e.g. /env0/observation:equiarm_msgs/msg/Observation");
        };
        // one type per topic: a bag channel, and a DDS topic, has one
        match topics.iter().find(|(n, _): &&(String, String)| n == name) {
            Some((_, other)) if other != ty => {
                bail!("topic '{name}' is named twice, as {other} and as {ty}: a topic has one type")
            }
            Some(_) => continue,
            None => topics.push((name.to_string(), ty.to_string())),
        }
    }
    let writer = equiarm_bag::WriterOptions {
        compression: a.compression.into(),
        split_bytes: a.split_size_mb.map(|m| m * 1_000_000),
        split_duration: a.split_duration_s.map(|s| s * 1_000_000_000),
        flush_interval: a.flush_ms * 1_000_000,
        ..Default::default()
    };
    let cfg = equiarm_nodes::recorder::RecordConfig {
        output: a.output,
        topics,
        all: a.all,
        foxglove: a.foxglove,
        polling_interval: Duration::from_millis(a.polling_interval_ms.max(1)),
        writer,
        status_every: (!a.quiet).then(|| Duration::from_secs(1)),
        duration: a.duration_s.map(Duration::from_secs_f64),
    };
    let opts = RosOptions::from_env()?;
    super::runtime()?.block_on(equiarm_nodes::recorder::run(&opts, cfg))?;
    Ok(ExitCode::SUCCESS)
}
