//! A decrypted private key handed to the DDS Security plugins without writing it to a file system.
//!
//! RustDDS's plugins read the key from a `file:` path and ignore the `dds.sec.auth.password`
//! property, so a password-protected key must reach them decrypted. [`KeyInMemory`] holds it in an
//! anonymous memory file (`memfd_create`): a new, private directory holds only a link `key.pem` to
//! `/proc/self/fd/N`, which leads to the key only in this process (another process following the
//! link reaches its own descriptor N; one of the same user allowed to trace this process could open
//! `/proc/PID/fd/N`, as it could read this process's memory). Both go when it is dropped, once the
//! participant is built (the plugins read the key once, while the participant is made).

use std::fs::File;
use std::io::Write;
use std::os::fd::{AsRawFd, FromRawFd};
use std::os::unix::fs::{DirBuilderExt, symlink};
use std::path::{Path, PathBuf};

use crate::Error;

/// A key in an anonymous memory file, and a directory whose `key.pem` reads it.
#[derive(Debug)]
pub struct KeyInMemory {
    _file: File,
    dir: PathBuf,
}

impl KeyInMemory {
    /// Puts `pem` into a new memory file.
    pub fn new(pem: &[u8]) -> Result<Self, Error> {
        let mem_err = |source| Error::Io { path: PathBuf::from("memfd:equiarm-key"), source };
        // SAFETY: a NUL-terminated name and valid flags; the returned descriptor is owned below.
        let fd = unsafe { libc::memfd_create(c"equiarm-key".as_ptr(), libc::MFD_CLOEXEC) };
        if fd < 0 {
            return Err(mem_err(std::io::Error::last_os_error()));
        }
        // SAFETY: `fd` is a new descriptor that nothing else owns.
        let mut file = unsafe { File::from_raw_fd(fd) };
        file.write_all(pem).map_err(mem_err)?;
        let dir = std::env::temp_dir().join(format!("equiarm-key-{}-{fd}", std::process::id()));
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&dir)
            .map_err(|source| Error::Io { path: dir.clone(), source })?;
        let link = dir.join("key.pem");
        let target = format!("/proc/self/fd/{}", file.as_raw_fd());
        if let Err(source) = symlink(&target, &link) {
            let _ = std::fs::remove_dir(&dir);
            return Err(Error::Io { path: link, source });
        }
        Ok(KeyInMemory { _file: file, dir })
    }

    /// The directory whose `key.pem` reads the key (in this process only).
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for KeyInMemory {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_reads_back_from_its_directory_and_goes_with_it() {
        let k = KeyInMemory::new(b"-----BEGIN PRIVATE KEY-----\nabc\n").unwrap();
        let dir = k.dir().to_path_buf();
        assert_eq!(std::fs::read(dir.join("key.pem")).unwrap(), b"-----BEGIN PRIVATE KEY-----\nabc\n");
        // the directory holds a link, not the key
        assert!(std::fs::symlink_metadata(dir.join("key.pem")).unwrap().file_type().is_symlink());
        drop(k);
        assert!(!dir.exists());
    }
}
