//! Reading bags: a rosbag2 directory (`NAME_0.mcap`, `NAME_1.mcap`, … in index order) or one `.mcap`
//! file. Complete files are read chunk by chunk through their summary's chunk index; a file without
//! its footer (a killed recorder), or whose summary cannot be read, record by record up to its last
//! complete record.
//!
//! A chunk that does not decode (a CRC mismatch, bad compression, a bad record inside) is skipped
//! whole and reported in [`ReadReport::lost`] with its time range and, where the file's message
//! index tells, its message count; every other chunk is still delivered. Only a damaged record
//! *frame* (a length that points nowhere) in a file read record by record ends that file's read.

use std::collections::BTreeMap;

use mcap::records::{self, Record};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use equiarm_types::files::at;

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
    /// Chunks skipped because they do not decode (salvage mode only).
    pub lost: Vec<LostChunk>,
    /// What each file gave, in read order.
    pub per_file: Vec<FileRead>,
}

/// What a read found in one file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FileRead {
    /// Messages delivered from it.
    pub messages: u64,
    /// Whether it ends with a valid footer.
    pub complete: bool,
    /// Compression of its first chunk (`""` when none was read).
    pub compression: String,
}

/// A chunk whose messages could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LostChunk {
    /// The file.
    pub path: PathBuf,
    /// Where the chunk record starts in the file (known when the file's chunk index was read).
    pub offset: Option<u64>,
    /// Log time of its first message, as its header or index says (ns since the epoch).
    pub start: Nanos,
    /// Log time of its last message.
    pub end: Nanos,
    /// Its message count, from the file's message index (None without one).
    pub messages: Option<u64>,
    /// What is wrong with it.
    pub reason: String,
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
    /// Messages read from it (damaged chunks not counted).
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
    /// Files that end early or damaged, with what was wrong.
    pub truncated: Vec<(PathBuf, String)>,
    /// Chunks that do not decode: their messages are not counted above.
    pub lost: Vec<LostChunk>,
    /// The bag directory's `metadata.yaml` checked against the files (`None`: a single file, or a
    /// directory without one).
    pub metadata: Option<crate::MetadataCheck>,
}

/// A bag opened for reading.
pub struct Reader {
    files: Vec<(PathBuf, memmap2::Mmap)>,
    /// Files of a bag directory that hold nothing (0 bytes: a recorder killed right at a split, or a
    /// full disk), skipped and reported by every read.
    empty: Vec<PathBuf>,
    /// The bag directory, when opened as one.
    dir: Option<PathBuf>,
}

fn split_index(name: &str) -> Option<u64> {
    let stem = name.strip_suffix(".mcap")?;
    let (_, n) = stem.rsplit_once('_')?;
    n.parse().ok()
}

impl Reader {
    /// Opens a bag directory or a single `.mcap` file. Fails, naming the file, if it is empty or not
    /// MCAP; in a directory, an empty file beside others is skipped (reads report it as truncated)
    /// and only a directory whose files are all empty fails.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let meta = std::fs::metadata(path).map_err(at(path))?;
        let mut paths = Vec::new();
        if meta.is_dir() {
            let mut indexed = Vec::new();
            for e in std::fs::read_dir(path).map_err(at(path))? {
                let e = e.map_err(at(path))?;
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
        let (mut files, mut empty) = (Vec::new(), Vec::new());
        for p in paths {
            let f = File::open(&p).map_err(at(&p))?;
            let len = f.metadata().map_err(at(&p))?.len();
            if len == 0 {
                empty.push(p);
                continue;
            }
            // SAFETY: the map is read-only; the crate docs tell users not to modify a bag while it is
            // read (a concurrent truncation could fault, as with any mmap reader).
            let map = unsafe { memmap2::Mmap::map(&f) }.map_err(at(&p))?;
            if !map.starts_with(MAGIC) {
                return Err(BagError::NotMcap { path: p });
            }
            files.push((p, map));
        }
        // (a single file that is empty leaves no file either)
        if let (true, Some(p)) = (files.is_empty(), empty.first()) {
            return Err(BagError::Empty { path: p.clone() });
        }
        Ok(Self { files, empty, dir: meta.is_dir().then(|| path.to_path_buf()) })
    }

    /// The files, in read order.
    pub fn paths(&self) -> Vec<&Path> {
        self.files.iter().map(|(p, _)| p.as_path()).collect()
    }

    /// Calls `f` with every message, file by file, in file order. In [`ReadMode::Strict`] a
    /// truncated file or a damaged chunk is an error (after the messages before it were delivered);
    /// in [`ReadMode::Salvage`] they are reported in the [`ReadReport`] and reading goes on.
    pub fn for_each<E>(
        &self,
        mode: ReadMode,
        mut f: impl FnMut(&RecordedMessage<'_>) -> Result<(), E>,
    ) -> Result<Result<ReadReport, E>, BagError> {
        let mut report = ReadReport::default();
        if let (ReadMode::Strict, Some(p)) = (mode, self.empty.first()) {
            return Err(BagError::Empty { path: p.clone() });
        }
        for p in &self.empty {
            report.truncated.push((p.clone(), "empty (0 bytes): nothing in it was read".into()));
        }
        for (path, map) in &self.files {
            let complete = map.len() >= 2 * MAGIC.len() && map.ends_with(MAGIC) && mcap::read::footer(map).is_ok();
            let summary = if complete { mcap::Summary::read(map).ok().flatten() } else { None };
            let before = report.messages;
            let mut compression = String::new();
            let read = match summary.filter(|s| !s.chunk_indexes.is_empty()) {
                Some(s) => {
                    let first = s.chunk_indexes.iter().min_by_key(|c| c.chunk_start_offset);
                    compression = first.map(|c| c.compression.clone()).unwrap_or_default();
                    read_indexed(path, map, &s, mode, &mut report, &mut f)?
                }
                None => read_linear(path, map, complete, mode, &mut report, &mut compression, &mut f)?,
            };
            if let Err(e) = read {
                return Ok(Err(e));
            }
            report.per_file.push(FileRead { messages: report.messages - before, complete, compression });
        }
        Ok(Ok(report))
    }

    /// Files, topics with types, counts and sizes, and the time span, from a full read (salvage mode,
    /// so a killed bag is described as far as it goes), and how `metadata.yaml` agrees with them.
    pub fn info(&self) -> Result<BagInfo, BagError> {
        let mut info = BagInfo::default();
        let report = self
            .for_each(ReadMode::Salvage, |m| {
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
        for ((path, map), read) in self.files.iter().zip(report.per_file) {
            let FileRead { messages, complete, compression } = read;
            info.files.push(FileInfo { path: path.clone(), size: map.len() as u64, messages, complete, compression });
        }
        for path in &self.empty {
            let none =
                FileInfo { path: path.clone(), size: 0, messages: 0, complete: false, compression: String::new() };
            info.files.push(none);
        }
        let order =
            |f: &FileInfo| f.path.file_name().and_then(|n| split_index(&n.to_string_lossy())).unwrap_or(u64::MAX);
        info.files.sort_by_key(order);
        (info.truncated, info.lost) = (report.truncated, report.lost);
        info.metadata = self.dir.as_deref().and_then(|d| crate::metadata_check::check(d, &info));
        Ok(info)
    }
}

/// The message records of the chunk record at `offset..offset + len` of `map`, decoded and
/// CRC-checked whole: an error anywhere loses the chunk, never a part of it.
fn chunk_at(map: &[u8], offset: u64, len: u64) -> Result<Vec<Record<'static>>, String> {
    let start = usize::try_from(offset).map_err(|_| "offset beyond memory".to_string())?;
    let end = usize::try_from(len)
        .ok()
        .and_then(|l| start.checked_add(l))
        .filter(|&e| e <= map.len() && e >= start + 9)
        .ok_or_else(|| format!("the index points outside the file ({} bytes)", map.len()))?;
    if map[start] != records::op::CHUNK {
        return Err(format!("no chunk record at byte {start} (opcode {:#04x})", map[start]));
    }
    match mcap::read::parse_record(records::op::CHUNK, &map[start + 9..end]).map_err(|e| e.to_string())? {
        Record::Chunk { header, data } => chunk_records(header, &data),
        _ => Err("not a chunk record".into()),
    }
}

/// Longest record read inside a chunk: 1 GiB, far above any message equiarm records (a paper-size
/// `PolicyWeights` is tens of MB), so a damaged length is refused instead of reserved.
pub const MAX_RECORD_LEN: u64 = 1 << 30;

/// Every record of a chunk (decompressed, its CRC checked at the end), owned.
///
/// Read through mcap's sans-io reader with a record length limit (the chunk's uncompressed size,
/// at most [`MAX_RECORD_LEN`]): mcap's `ChunkReader` has none and reserved whatever length a record
/// inside the chunk gave, up to 2^64 bytes, before finding the data short, which aborted the process.
fn chunk_records(header: records::ChunkHeader, data: &[u8]) -> Result<Vec<Record<'static>>, String> {
    // the chunk record as a file holds it: opcode, length, then the header fields and the records
    let mut body = Vec::with_capacity(36 + header.compression.len() + data.len());
    body.extend(header.message_start_time.to_le_bytes());
    body.extend(header.message_end_time.to_le_bytes());
    body.extend(header.uncompressed_size.to_le_bytes());
    body.extend(header.uncompressed_crc.to_le_bytes());
    body.extend((header.compression.len() as u32).to_le_bytes());
    body.extend(header.compression.as_bytes());
    body.extend((data.len() as u64).to_le_bytes());
    body.extend(data);
    let mut record = vec![records::op::CHUNK];
    record.extend((body.len() as u64).to_le_bytes());
    record.extend(body);
    // (never below the chunk header's own length, which the reader checks against the same limit)
    let header_len = 40 + header.compression.len() as u64;
    let limit = usize::try_from(header.uncompressed_size.min(MAX_RECORD_LEN).max(header_len)).unwrap_or(usize::MAX);
    let options = mcap::sans_io::LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_validate_chunk_crcs(true)
        .with_record_length_limit(limit);
    let mut reader = mcap::sans_io::LinearReader::new_with_options(options);
    let mut rest = record.as_slice();
    let mut out = Vec::new();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| e.to_string())? {
            mcap::sans_io::LinearReadEvent::ReadRequest(need) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                out.push(mcap::read::parse_record(opcode, data).map_err(|e| e.to_string())?.into_owned());
            }
        }
    }
    Ok(out)
}

/// Hands one decoded message record to `f`; `channel` is its channel.
fn deliver<E>(
    channel: &Arc<mcap::Channel<'static>>,
    header: &records::MessageHeader,
    data: &[u8],
    f: &mut impl FnMut(&RecordedMessage<'_>) -> Result<(), E>,
) -> Result<(), E> {
    let type_name = channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
    f(&RecordedMessage {
        topic: &channel.topic,
        type_name,
        channel,
        log_time: header.log_time,
        publish_time: header.publish_time,
        sequence: header.sequence,
        data,
    })
}

/// A complete file, chunk by chunk through its summary's chunk index (channels from the summary).
fn read_indexed<E>(
    path: &Path,
    map: &[u8],
    summary: &mcap::Summary,
    mode: ReadMode,
    report: &mut ReadReport,
    f: &mut impl FnMut(&RecordedMessage<'_>) -> Result<(), E>,
) -> Result<Result<(), E>, BagError> {
    let mut chunks: Vec<&records::ChunkIndex> = summary.chunk_indexes.iter().collect();
    chunks.sort_by_key(|c| c.chunk_start_offset);
    for idx in chunks {
        let decoded = chunk_at(map, idx.chunk_start_offset, idx.chunk_length).and_then(|recs| {
            // every message's channel must be known before any is delivered
            let mut out = Vec::new();
            for r in recs {
                if let Record::Message { header, data } = r {
                    let ch = summary.channels.get(&header.channel_id).ok_or_else(|| {
                        format!("message {} refers to unknown channel {}", header.sequence, header.channel_id)
                    })?;
                    out.push((ch, header, data));
                }
            }
            Ok(out)
        });
        match decoded {
            Ok(messages) => {
                for (ch, header, data) in messages {
                    if let Err(e) = deliver(ch, &header, &data, f) {
                        return Ok(Err(e));
                    }
                    report.messages += 1;
                }
            }
            Err(reason) => {
                if mode == ReadMode::Strict {
                    return Err(BagError::CorruptChunk {
                        path: path.into(),
                        offset: Some(idx.chunk_start_offset),
                        reason,
                    });
                }
                let messages =
                    summary.read_message_indexes(map, idx).ok().map(|ix| ix.values().map(|v| v.len() as u64).sum());
                report.lost.push(LostChunk {
                    path: path.into(),
                    offset: Some(idx.chunk_start_offset),
                    start: idx.message_start_time,
                    end: idx.message_end_time,
                    messages,
                    reason,
                });
            }
        }
    }
    Ok(Ok(()))
}

/// A file read record by record (no footer, or a summary that cannot be read): damaged chunks are
/// skipped; a damaged record frame ends the file.
fn read_linear<E>(
    path: &Path,
    map: &[u8],
    complete: bool,
    mode: ReadMode,
    report: &mut ReadReport,
    compression: &mut String,
    f: &mut impl FnMut(&RecordedMessage<'_>) -> Result<(), E>,
) -> Result<Result<(), E>, BagError> {
    let mut first_chunk = true;
    let reader = mcap::read::LinearReader::new_with_options(map, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|cause| BagError::Mcap { path: path.into(), messages: 0, cause })?;
    let mut channels = mcap::read::ChannelAccumulator::<'static>::default();
    let (mut in_file, mut ended) = (0u64, None::<String>);
    'records: for r in reader {
        let r = match r {
            Ok(r) => r,
            Err(e) => {
                ended = Some(e.to_string());
                break;
            }
        };
        let inner: Vec<Record<'static>> = match r {
            Record::Chunk { header, data } => {
                if std::mem::take(&mut first_chunk) {
                    compression.clone_from(&header.compression);
                }
                let (start, end) = (header.message_start_time, header.message_end_time);
                match chunk_records(header, &data) {
                    Ok(recs) => recs,
                    Err(reason) => {
                        if mode == ReadMode::Strict {
                            return Err(BagError::CorruptChunk { path: path.into(), offset: None, reason });
                        }
                        report.lost.push(LostChunk {
                            path: path.into(),
                            offset: None,
                            start,
                            end,
                            messages: None,
                            reason,
                        });
                        continue;
                    }
                }
            }
            Record::DataEnd(_) => break,
            other => vec![other.into_owned()],
        };
        for r in inner {
            let step = match r {
                Record::Schema { header, data } => channels.add_schema(header, data).map(|_| None),
                Record::Channel(c) => channels.add_channel(c).map(|_| None),
                Record::Message { header, data } => match channels.get(header.channel_id) {
                    Some(ch) => Ok(Some((ch, header, data))),
                    None => Err(mcap::McapError::UnknownChannel(header.sequence, header.channel_id)),
                },
                _ => Ok(None),
            };
            match step {
                Ok(Some((ch, header, data))) => {
                    if let Err(e) = deliver(&ch, &header, &data, f) {
                        return Ok(Err(e));
                    }
                    in_file += 1;
                    report.messages += 1;
                }
                Ok(None) => {}
                Err(e) => {
                    ended = Some(e.to_string());
                    break 'records;
                }
            }
        }
    }
    let reason = match ended {
        Some(reason) => reason,
        None if complete => return Ok(Ok(())),
        None => "no footer or end magic".into(),
    };
    match mode {
        ReadMode::Strict => Err(BagError::Truncated { path: path.into(), messages: in_file, reason }),
        ReadMode::Salvage => {
            report.truncated.push((path.into(), reason));
            Ok(Ok(()))
        }
    }
}
