//! Writing a rosbag2 MCAP bag directory. See the crate docs for the layout.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use equiarm_types::files::{at, replace};

use crate::metadata::{BagMeta, FileMeta, TopicMeta};
use crate::{BagError, Nanos};

/// Chunk compression.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Compression {
    /// No compression (fastest; what `ros2 bag record` does by default).
    None,
    /// LZ4 frames: cheap, ~2.5x on camera data.
    Lz4,
    /// Zstandard: ~4x on camera data at a few times lz4's CPU.
    #[default]
    Zstd,
}

impl Compression {
    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::None => None,
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::Zstd => Some(mcap::Compression::Zstd),
        }
    }
}

/// How a bag is written.
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// zstd level (1..=19; 3 is zstd's default).
    pub zstd_level: u32,
    /// zstd worker threads (0: compress on the writing thread). Set explicitly so a recorder never
    /// spawns one worker per core beside control loops.
    pub compression_threads: u32,
    /// Uncompressed bytes per chunk (rosbag2 uses 768 KiB).
    pub chunk_size: u64,
    /// Start a new file once this many payload bytes were written to the current one.
    pub split_bytes: Option<u64>,
    /// Start a new file once the current one spans this many nanoseconds of log time.
    pub split_duration: Option<Nanos>,
    /// Close the open chunk and flush to the OS at least this often (ns of the clock given to
    /// [`Writer::flush_if_due`]): a killed recorder loses at most this much.
    pub flush_interval: Nanos,
    /// `ros_distro` recorded in the metadata.
    pub ros_distro: String,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Zstd,
            zstd_level: 3,
            compression_threads: 0,
            chunk_size: 1 << 20,
            split_bytes: None,
            split_duration: None,
            flush_interval: 250_000_000,
            ros_distro: "jazzy".into(),
        }
    }
}

/// A topic as recorded: its name, type and schema, and its publishers' QoS.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicInfo {
    /// Fully qualified topic name, e.g. `/env0/observation`.
    pub name: String,
    /// ROS 2 type name, e.g. `equiarm_msgs/msg/Observation`.
    pub type_name: String,
    /// Schema encoding: `ros2msg` (or whatever the source bag had).
    pub schema_encoding: String,
    /// Schema data: the concatenated definition text for `ros2msg`.
    pub schema: Vec<u8>,
    /// `offered_qos_profiles` YAML (see [`crate::qos::offered_qos_yaml`]).
    pub offered_qos: String,
    /// REP-2011 type hash `RIHS01_…`, or empty.
    pub type_hash: String,
}

impl TopicInfo {
    /// A topic carrying `M`, with the schema from its `.msg` definition.
    pub fn of<M: equiarm_msgs::RosMessage>(name: &str, qos: &[crate::qos::OfferedQos]) -> Self {
        Self {
            name: name.into(),
            type_name: M::TYPE_NAME.into(),
            schema_encoding: "ros2msg".into(),
            schema: M::DEFINITION.as_bytes().to_vec(),
            offered_qos: crate::qos::offered_qos_yaml(qos),
            type_hash: String::new(),
        }
    }
}

/// Handle of a topic added to a [`Writer`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TopicId(usize);

/// What a finished bag holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BagSummary {
    /// The bag directory.
    pub dir: PathBuf,
    /// File names inside it.
    pub files: Vec<String>,
    /// Messages per topic, in the order topics were added.
    pub topics: Vec<(String, u64)>,
    /// All messages.
    pub messages: u64,
}

struct TopicState {
    info: TopicInfo,
    count: u64,
    channel: Option<u16>,
    sequence: u32,
}

struct OpenFile {
    path: PathBuf,
    mcap: mcap::Writer<BufWriter<File>>,
    schemas: HashMap<String, u16>,
    bytes: u64,
}

/// Writes one bag directory. Call [`Writer::finish`] at the end; without it (a crash) the complete
/// chunks are on disk and [`crate::recover`] rebuilds the rest.
pub struct Writer {
    dir: PathBuf,
    name: String,
    opts: WriterOptions,
    topics: Vec<TopicState>,
    files: Vec<FileMeta>,
    open: Option<OpenFile>,
    last_flush: Option<Nanos>,
    finished: bool,
}

impl Writer {
    /// Creates the bag directory `dir` (it must not exist, or be empty) and its first file.
    pub fn create(dir: &Path, opts: WriterOptions) -> Result<Self, BagError> {
        if dir.exists() {
            let mut entries = std::fs::read_dir(dir).map_err(at(dir))?;
            if entries.next().is_some() {
                return Err(BagError::Exists { path: dir.into() });
            }
        }
        std::fs::create_dir_all(dir).map_err(at(dir))?;
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .filter(|n| !n.is_empty() && n != "..")
            .ok_or_else(|| BagError::Usage { path: dir.into(), what: "a bag directory needs a name".into() })?;
        let mut w = Writer {
            dir: dir.into(),
            name,
            opts,
            topics: Vec::new(),
            files: Vec::new(),
            open: None,
            last_flush: None,
            finished: false,
        };
        w.open_file()?;
        Ok(w)
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn meta(&self) -> BagMeta {
        BagMeta {
            topics: self
                .topics
                .iter()
                .map(|t| TopicMeta {
                    name: t.info.name.clone(),
                    type_name: t.info.type_name.clone(),
                    offered_qos: t.info.offered_qos.clone(),
                    type_hash: t.info.type_hash.clone(),
                    count: t.count,
                })
                .collect(),
            files: self.files.clone(),
            ros_distro: self.opts.ros_distro.clone(),
        }
    }

    fn rosbag2_record(&self, at_open: bool) -> mcap::records::Metadata {
        let yaml = self.meta().serialized(at_open);
        mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: BTreeMap::from([("serialized_metadata".into(), yaml)]),
        }
    }

    fn open_file(&mut self) -> Result<(), BagError> {
        let file_name = format!("{}_{}.mcap", self.name, self.files.len());
        let path = self.dir.join(&file_name);
        let file = File::create(&path).map_err(at(&path))?;
        let mut options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("equiarm_bag ", env!("CARGO_PKG_VERSION")))
            .compression(self.opts.compression.mcap())
            .chunk_size(Some(self.opts.chunk_size));
        if self.opts.compression == Compression::Zstd {
            options =
                options.compression_level(self.opts.zstd_level).compression_threads(self.opts.compression_threads);
        }
        let mut mcap = options.create(BufWriter::with_capacity(1 << 20, file)).map_err(BagError::write(&path))?;
        mcap.write_metadata(&self.rosbag2_record(true)).map_err(BagError::write(&path))?;
        self.files.push(FileMeta { path: file_name, start: 0, end: 0, count: 0 });
        self.open = Some(OpenFile { path, mcap, schemas: HashMap::new(), bytes: 0 });
        for t in &mut self.topics {
            t.channel = None;
        }
        for i in 0..self.topics.len() {
            self.channel_of(i)?;
        }
        Ok(())
    }

    /// The channel of topic `i` in the open file, registering schema and channel there if needed.
    fn channel_of(&mut self, i: usize) -> Result<u16, BagError> {
        if let Some(c) = self.topics[i].channel {
            return Ok(c);
        }
        let f = self
            .open
            .as_mut()
            .ok_or_else(|| BagError::Usage { path: self.dir.clone(), what: "bag is finished".into() })?;
        let t = &self.topics[i].info;
        let schema = match f.schemas.get(&t.type_name) {
            Some(&s) => s,
            None => {
                let s =
                    f.mcap.add_schema(&t.type_name, &t.schema_encoding, &t.schema).map_err(BagError::write(&f.path))?;
                f.schemas.insert(t.type_name.clone(), s);
                s
            }
        };
        let metadata = BTreeMap::from([
            ("offered_qos_profiles".to_string(), t.offered_qos.clone()),
            ("topic_type_hash".to_string(), t.type_hash.clone()),
        ]);
        let c = f.mcap.add_channel(schema, &t.name, "cdr", &metadata).map_err(BagError::write(&f.path))?;
        self.topics[i].channel = Some(c);
        Ok(c)
    }

    /// Adds a topic (its schema and channel are written at once, so they survive a crash).
    pub fn add_topic(&mut self, info: TopicInfo) -> Result<TopicId, BagError> {
        if let Some(i) = self.topics.iter().position(|t| t.info.name == info.name && t.info.type_name == info.type_name)
        {
            return Ok(TopicId(i));
        }
        self.topics.push(TopicState { info, count: 0, channel: None, sequence: 0 });
        let i = self.topics.len() - 1;
        self.channel_of(i)?;
        Ok(TopicId(i))
    }

    /// Writes one message: `data` is its CDR payload (encapsulation header included), `log_time` the
    /// receive time, `publish_time` the source time, both ns since the epoch.
    pub fn write(&mut self, topic: TopicId, log_time: Nanos, publish_time: Nanos, data: &[u8]) -> Result<(), BagError> {
        if topic.0 >= self.topics.len() {
            return Err(BagError::Usage { path: self.dir.clone(), what: format!("unknown topic id {}", topic.0) });
        }
        if self.split_due(log_time) {
            self.close_file()?;
            self.open_file()?;
        }
        let channel = self.channel_of(topic.0)?;
        let t = &mut self.topics[topic.0];
        let f = self.open.as_mut().expect("channel_of checked the file is open");
        let header = mcap::records::MessageHeader { channel_id: channel, sequence: t.sequence, log_time, publish_time };
        f.mcap.write_to_known_channel(&header, data).map_err(BagError::write(&f.path))?;
        t.sequence = t.sequence.wrapping_add(1);
        t.count += 1;
        f.bytes += data.len() as u64;
        let fm = self.files.last_mut().expect("a file is open");
        if fm.count == 0 {
            fm.start = log_time;
            fm.end = log_time;
        }
        fm.start = fm.start.min(log_time);
        fm.end = fm.end.max(log_time);
        fm.count += 1;
        Ok(())
    }

    fn split_due(&self, log_time: Nanos) -> bool {
        let (Some(f), Some(fm)) = (&self.open, self.files.last()) else { return false };
        if fm.count == 0 {
            return false;
        }
        self.opts.split_bytes.is_some_and(|b| f.bytes >= b)
            || self.opts.split_duration.is_some_and(|d| log_time.saturating_sub(fm.start) >= d)
    }

    /// Closes the open chunk and hands everything to the OS if the flush interval has passed since
    /// the last flush (`now` on any monotonic clock, in ns). Returns whether it flushed.
    pub fn flush_if_due(&mut self, now: Nanos) -> Result<bool, BagError> {
        match self.last_flush {
            Some(t) if now.saturating_sub(t) < self.opts.flush_interval => Ok(false),
            _ => {
                self.flush()?;
                self.last_flush = Some(now);
                Ok(true)
            }
        }
    }

    /// Closes the open chunk and hands everything written so far to the OS.
    pub fn flush(&mut self) -> Result<(), BagError> {
        if let Some(f) = self.open.as_mut() {
            f.mcap.flush().map_err(BagError::write(&f.path))?;
        }
        Ok(())
    }

    fn close_file(&mut self) -> Result<(), BagError> {
        let record = self.rosbag2_record(false);
        if let Some(mut f) = self.open.take() {
            f.mcap.write_metadata(&record).map_err(BagError::write(&f.path))?;
            f.mcap.finish().map_err(BagError::write(&f.path))?;
            let mut buf = f.mcap.into_inner();
            buf.flush().map_err(at(&f.path))?;
            let file = buf.into_inner().map_err(|e| at(&f.path)(e.into_error()))?;
            file.sync_all().map_err(at(&f.path))?;
        }
        Ok(())
    }

    /// Finishes the bag: the last file gets its summary and indexes, then `metadata.yaml` is written
    /// (through a temporary file and a rename, so it is either complete or absent).
    pub fn finish(mut self) -> Result<BagSummary, BagError> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<BagSummary, BagError> {
        self.close_file()?;
        self.finished = true;
        let yaml = self.meta().yaml_file();
        replace(&self.dir.join("metadata.yaml"), yaml)?;
        Ok(BagSummary {
            dir: self.dir.clone(),
            files: self.files.iter().map(|f| f.path.clone()).collect(),
            topics: self.topics.iter().map(|t| (t.info.name.clone(), t.count)).collect(),
            messages: self.topics.iter().map(|t| t.count).sum(),
        })
    }
}

impl Drop for Writer {
    /// A writer dropped without [`Writer::finish`] (an error path, a panic) still finishes the bag.
    fn drop(&mut self) {
        if !self.finished
            && let Err(e) = self.finish_inner()
        {
            log::error!("finishing bag {} on drop: {e}", self.dir.display());
        }
    }
}
