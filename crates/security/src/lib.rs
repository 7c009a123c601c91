//! DDS Security for the suite, the ROS 2 way (SROS2): keystores with one CA for identities and
//! permissions ([`keystore`]), each node's enclave with its X.509 identity and the permissions of its
//! place in the topic graph ([`graph`], [`documents`]), and the checks a node runs on its enclave
//! before it joins a secured domain ([`check`]). No ROS here; the nodes hand the checked files to the
//! DDS Security plugins (docs/security.md).

pub mod check;
pub mod documents;
pub mod graph;
pub mod keystore;
pub mod memory;
pub mod xml;

use std::path::{Path, PathBuf};

pub use check::{Enclave, check_enclave};
pub use graph::{EnclaveName, Grant, Role};
pub use keystore::{KEY_PASSWORD_VAR, KeyPassword, Keystore};
pub use memory::KeyInMemory;

/// What went wrong, naming the file or the name at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file that cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A file that is there but wrong.
    #[error("{path}: {why}")]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        why: String,
    },
    /// A directory that is not a keystore.
    #[error("{root} is not a keystore: {missing} is missing (create one with `equiarm security create-keystore`)")]
    NotAKeystore {
        /// The directory.
        root: PathBuf,
        /// The first file it lacks.
        missing: PathBuf,
    },
    /// A keystore where a new one was to be made.
    #[error("{0} already holds a keystore")]
    KeystoreExists(PathBuf),
    /// A bad enclave name.
    #[error("enclave name '{name}': {why}")]
    EnclaveName {
        /// The name as given.
        name: String,
        /// What is wrong with it.
        why: String,
    },
    /// An OpenSSL failure while making keys, certificates or signatures.
    #[error("{what}: {source}")]
    Ssl {
        /// What was being done.
        what: &'static str,
        /// OpenSSL's errors.
        source: openssl::error::ErrorStack,
    },
}

pub(crate) fn io_error(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io { path: path.to_path_buf(), source }
}

pub(crate) fn ssl_error(what: &'static str) -> impl Fn(openssl::error::ErrorStack) -> Error {
    move |source| Error::Ssl { what, source }
}
