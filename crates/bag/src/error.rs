//! The bag crate's error: every variant names the file (or directory) it is about.

use std::path::PathBuf;

use equiarm_types::files::FileError;

/// What went wrong with a bag, and where.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// Reading or writing the file system failed (the file or directory, and the cause).
    #[error(transparent)]
    Io(#[from] FileError),
    /// rosbag2 never records into an existing directory; neither do we.
    #[error("{path}: already exists and is not empty (a bag is written into a new directory)")]
    Exists {
        /// The bag directory, which already has entries.
        path: PathBuf,
    },
    /// The path holds no MCAP files.
    #[error("{path}: no MCAP files (expected NAME_0.mcap, NAME_1.mcap, ... or a .mcap file)")]
    NoFiles {
        /// The directory that was opened as a bag.
        path: PathBuf,
    },
    /// The file is empty.
    #[error("{path}: empty file, not an MCAP bag")]
    Empty {
        /// The zero-length file.
        path: PathBuf,
    },
    /// The file does not start with the MCAP magic bytes.
    #[error("{path}: not an MCAP file (no MCAP magic at the start)")]
    NotMcap {
        /// The file without the magic.
        path: PathBuf,
    },
    /// The file ends before its footer (a recorder that was killed) and the read was strict.
    #[error("{path}: truncated after {messages} readable messages ({reason}); `equiarm bag recover` rewrites it whole")]
    Truncated {
        /// The truncated MCAP file.
        path: PathBuf,
        /// Messages read from this file before it ended.
        messages: u64,
        /// Why the read stopped: the MCAP reader's error, or `no footer or end magic`.
        reason: String,
    },
    /// The MCAP structure is damaged.
    #[error("{path}: damaged MCAP data after {messages} messages: {cause}")]
    Mcap {
        /// The damaged MCAP file.
        path: PathBuf,
        /// Messages read from this file before the damage (0 if it could not be opened as a stream).
        messages: u64,
        /// The MCAP reader's error.
        cause: mcap::McapError,
    },
    /// A chunk cannot be read (bad CRC, compression or records) and the read was strict.
    #[error("{path}: a chunk{} is damaged ({reason}); `equiarm bag recover` keeps every intact chunk", offset.map(|o| format!(" at byte {o}")).unwrap_or_default())]
    CorruptChunk {
        /// The MCAP file.
        path: PathBuf,
        /// Where the chunk record starts in the file, if known.
        offset: Option<u64>,
        /// What is wrong with it.
        reason: String,
    },
    /// Writing MCAP records failed.
    #[error("{path}: writing MCAP: {cause}")]
    Write {
        /// The MCAP file being written.
        path: PathBuf,
        /// The MCAP writer's error.
        cause: mcap::McapError,
    },
    /// A message refers to a topic id this writer never handed out, or similar misuse.
    #[error("{path}: {what}")]
    Usage {
        /// The bag directory.
        path: PathBuf,
        /// What was misused, e.g. `unknown topic id 3` or `bag is finished`.
        what: String,
    },
}

impl BagError {
    pub(crate) fn write(path: impl Into<PathBuf>) -> impl FnOnce(mcap::McapError) -> BagError {
        let path = path.into();
        move |cause| BagError::Write { path, cause }
    }
}
