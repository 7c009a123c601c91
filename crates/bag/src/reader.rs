//! Reading bags: a rosbag2 directory (`NAME_0.mcap`, `NAME_1.mcap`, … in index order) or one `.mcap`
//! file. Complete files are read through their summary; a file without its footer (a killed
//! recorder) is read record by record up to its last complete chunk.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::{BagError, Nanos};

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// What to do with a file whose end is missing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadMode {
    /// Fail with [`BagError::Truncated`] after delivering what was readable.
    Strict,
    /// Deliver every complete chunk and report the damage in [`ReadReport::truncated`].
    Salvage,
}

/// One message as stored.
#[derive(Debug)]
pub struct RecordedMessage<'a> {
    /// Topic name.
    pub topic: &'a str,
    /// ROS 2 type name (the schema's name), e.g. `equiarm_msgs/msg/Observation`.
    pub type_name: &'a str,
    /// The channel (topic, schema, QoS metadata) the message belongs to.
    pub channel: &'a Arc<mcap::Channel<'static>>,
    /// Receive time, ns since the epoch.
    pub log_time: Nanos,
    /// Source (publish) time, ns since the epoch.
    pub publish_time: Nanos,
    /// Per-channel sequence number.
    pub sequence: u32,
    /// CDR payload, encapsulation header included.
    pub data: &'a [u8],
}

/// What a read delivered.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ReadReport {
    /// Messages delivered.
    pub messages: u64,
    /// Files whose end was missing or damaged, with what was wrong (salvage mode only).
    pub truncated: Vec<(PathBuf, String)>,
}

/// Message counts and times of one topic.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TopicStats {
    /// ROS 2 type name.
    pub type_name: String,
    /// Messages recorded.
    pub count: u64,
    /// Payload bytes recorded.
    pub bytes: u64,
    /// `offered_qos_profiles` channel metadata.
    pub offered_qos: String,
}

/// One file of a bag.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileInfo {
    /// Its path.
    pub path: PathBuf,
    /// Size on disk, bytes.
    pub size: u64,
    /// Messages read from it.
    pub messages: u64,
    /// Whether it ends with a valid footer (a file from a killed recorder does not).
    pub complete: bool,
    /// Compression of its chunks (`""`, `zstd`, `lz4`; the first chunk's).
    pub compression: String,
}

/// What `equiarm bag info` shows.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BagInfo {
    /// Files in read order.
    pub files: Vec<FileInfo>,
    /// Topics by name.
    pub topics: BTreeMap<String, TopicStats>,
    /// First and last log time, ns since the epoch (0 when empty).
    pub start: Nanos,
    /// Last log time.
    pub end: Nanos,
    /// All messages.
    pub messages: u64,
}

/// A bag opened for reading.
pub struct Reader {
    files: Vec<(PathBuf, memmap2::Mmap)>,
}

fn split_index(name: &str) -> Option<u64> {
    let stem = name.strip_suffix(".mcap")?;
    let (_, n) = stem.rsplit_once('_')?;
    n.parse().ok()
}

impl Reader {
    /// Opens a bag directory or a single `.mcap` file. Fails, naming the file, if it is empty or not
    /// MCAP.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let meta = std::fs::metadata(path).map_err(BagError::io(path))?;
        let mut paths = Vec::new();
        if meta.is_dir() {
            let mut indexed = Vec::new();
            for e in std::fs::read_dir(path).map_err(BagError::io(path))? {
                let e = e.map_err(BagError::io(path))?;
                let name = e.file_name().to_string_lossy().to_string();
                if let Some(i) = split_index(&name) {
                    indexed.push((i, e.path()));
                } else if name.ends_with(".mcap") {
                    indexed.push((u64::MAX, e.path()));
                }
            }
            indexed.sort();
            paths.extend(indexed.into_iter().map(|(_, p)| p));
        } else {
            paths.push(path.to_path_buf());
        }
        if paths.is_empty() {
            return Err(BagError::NoFiles { path: path.into() });
        }
        let mut files = Vec::new();
        for p in paths {
            let f = File::open(&p).map_err(BagError::io(&p))?;
            let len = f.metadata().map_err(BagError::io(&p))?.len();
            if len == 0 {
                return Err(BagError::Empty { path: p });
            }
            // SAFETY: the map is read-only; the crate docs tell users not to modify a bag while it is
            // read (a concurrent truncation could fault, as with any mmap reader).
            let map = unsafe { memmap2::Mmap::map(&f) }.map_err(BagError::io(&p))?;
            if !map.starts_with(MAGIC) {
                return Err(BagError::NotMcap { path: p });
            }
            files.push((p, map));
        }
        Ok(Self { files })
    }

    /// The files, in read order.
    pub fn paths(&self) -> Vec<&Path> {
        self.files.iter().map(|(p, _)| p.as_path()).collect()
    }

    /// Calls `f` with every message, file by file, in file order.
    pub fn for_each<E>(
        &self,
        mode: ReadMode,
        mut f: impl FnMut(&RecordedMessage<'_>) -> Result<(), E>,
    ) -> Result<Result<ReadReport, E>, BagError> {
        let mut report = ReadReport::default();
        for (path, map) in &self.files {
            let complete = map.len() >= 2 * MAGIC.len() && map.ends_with(MAGIC) && mcap::read::footer(map).is_ok();
            let options = if complete {
                mcap::read::Options::ValidateChunkCrcs.into()
            } else {
                mcap::read::Options::IgnoreEndMagic.into()
            };
            let stream = mcap::MessageStream::new_with_options(map, options).map_err(|source| BagError::Mcap {
                path: path.clone(),
                messages: 0,
                source,
            })?;
            let mut in_file = 0u64;
            for m in stream {
                let m = match m {
                    Ok(m) => m,
                    Err(source) => {
                        let reason = source.to_string();
                        if complete {
                            return Err(BagError::Mcap { path: path.clone(), messages: in_file, source });
                        }
                        match mode {
                            ReadMode::Strict => {
                                return Err(BagError::Truncated { path: path.clone(), messages: in_file, reason });
                            }
                            ReadMode::Salvage => {
                                report.truncated.push((path.clone(), reason));
                                break;
                            }
                        }
                    }
                };
                let type_name = m.channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
                let rm = RecordedMessage {
                    topic: &m.channel.topic,
                    type_name,
                    channel: &m.channel,
                    log_time: m.log_time,
                    publish_time: m.publish_time,
                    sequence: m.sequence,
                    data: match &m.data {
                        Cow::Borrowed(b) => b,
                        Cow::Owned(v) => v.as_slice(),
                    },
                };
                if let Err(e) = f(&rm) {
                    return Ok(Err(e));
                }
                in_file += 1;
                report.messages += 1;
            }
            if !complete && !report.truncated.iter().any(|(p, _)| p == path) {
                // the stream ended cleanly at a data end record but the footer is missing
                match mode {
                    ReadMode::Strict => {
                        return Err(BagError::Truncated {
                            path: path.clone(),
                            messages: in_file,
                            reason: "no footer or end magic".into(),
                        });
                    }
                    ReadMode::Salvage => report.truncated.push((path.clone(), "no footer or end magic".into())),
                }
            }
        }
        Ok(Ok(report))
    }

    /// Files, topics with types, counts and sizes, and the time span, from a full read (salvage mode,
    /// so a killed bag is described as far as it goes).
    pub fn info(&self) -> Result<BagInfo, BagError> {
        let mut info = BagInfo::default();
        self.for_each(ReadMode::Salvage, |m| {
            let t = info.topics.entry(m.topic.to_string()).or_default();
            if t.count == 0 {
                t.type_name = m.type_name.to_string();
                t.offered_qos = m.channel.metadata.get("offered_qos_profiles").cloned().unwrap_or_default();
            }
            t.count += 1;
            t.bytes += m.data.len() as u64;
            if info.messages == 0 || m.log_time < info.start {
                info.start = m.log_time;
            }
            info.end = info.end.max(m.log_time);
            info.messages += 1;
            Ok::<(), std::convert::Infallible>(())
        })?
        .unwrap_or_else(|e| match e {});
        for (path, map) in &self.files {
            let complete = map.ends_with(MAGIC) && mcap::read::footer(map).is_ok();
            let (mut messages, mut compression) = (0, String::new());
            if complete {
                if let Ok(Some(s)) = mcap::Summary::read(map) {
                    messages = s.stats.as_ref().map(|st| st.message_count).unwrap_or(0);
                    compression = s.chunk_indexes.first().map(|c| c.compression.clone()).unwrap_or_default();
                }
            } else {
                messages = count_salvageable(map);
            }
            info.files.push(FileInfo { path: path.clone(), size: map.len() as u64, messages, complete, compression });
        }
        Ok(info)
    }
}

fn count_salvageable(map: &[u8]) -> u64 {
    let Ok(stream) = mcap::MessageStream::new_with_options(map, mcap::read::Options::IgnoreEndMagic.into()) else {
        return 0;
    };
    stream.take_while(|m| m.is_ok()).count() as u64
}
