//! Files, the same way in every crate: one error for a file operation that failed ([`FileError`],
//! made by [`at`]), and one way to write a file whole or not at all ([`write_atomically`],
//! [`replace`]).

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// A file operation that failed: the file (or directory) and the operating system's error. The
/// cause is in the message, not chained as a source, so it is printed once.
#[derive(Debug, thiserror::Error)]
#[error("{}: {cause}", path.display())]
pub struct FileError {
    /// The file or directory.
    pub path: PathBuf,
    /// What the operating system said.
    pub cause: io::Error,
}

/// The [`FileError`] of an I/O error about `path`, for `map_err`:
/// `std::fs::read(&p).map_err(at(&p))?`.
pub fn at(path: impl AsRef<Path>) -> impl FnOnce(io::Error) -> FileError {
    let path = path.as_ref().to_path_buf();
    move |cause| {
        // A directory where a file was expected: the system's words for it vary with the call
        // ("Is a directory" for a read, "No such device" for a memory map), so say it plainly.
        const ENODEV: i32 = 19;
        const EISDIR: i32 = 21;
        let cause = match cause.raw_os_error() {
            Some(ENODEV | EISDIR) if path.is_dir() => {
                io::Error::new(cause.kind(), "is a directory, where a file was expected")
            }
            _ => cause,
        };
        FileError { path, cause }
    }
}

/// Writes `path` whole or not at all: `write` fills `NAME.tmp` beside it (buffered), which is
/// synced and renamed over `path`, and the directory is synced; if anything fails the temporary
/// file is removed and `path` keeps what it held. The error names the file that failed.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<(), FileError> {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    let tmp = path.with_file_name(name);
    let written = File::create(&tmp).and_then(|f| {
        let mut w = BufWriter::new(f);
        write(&mut w)?;
        w.into_inner().map_err(io::IntoInnerError::into_error)?.sync_all()
    });
    if let Err(cause) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(FileError { path: tmp, cause });
    }
    std::fs::rename(&tmp, path).map_err(at(path))?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && let Ok(d) = File::open(dir)
    {
        // (a directory sync is not supported everywhere; the rename is done either way)
        let _ = d.sync_all();
    }
    Ok(())
}

/// [`write_atomically`] with `bytes` as the whole file.
pub fn replace(path: &Path, bytes: impl AsRef<[u8]>) -> Result<(), FileError> {
    write_atomically(path, |w| w.write_all(bytes.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("equiarm-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Regression (issue 61): a directory given for a file was reported as "No such device (os
    /// error 19)" (a memory map's words); it is named as a directory.
    #[test]
    fn a_directory_given_for_a_file_is_named_as_one() {
        let d = scratch("dir");
        let e = std::fs::read(&d).map_err(at(&d)).unwrap_err();
        assert!(e.to_string().ends_with(": is a directory, where a file was expected"), "{e}");
        let missing = d.join("nothing");
        let e = std::fs::read(&missing).map_err(at(&missing)).unwrap_err();
        assert!(e.to_string().contains("No such file"), "{e}");
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_leaves_no_temporary() {
        let d = scratch("fail");
        let p = d.join("state.json");
        replace(&p, "old").unwrap();
        let e = write_atomically(&p, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(e.to_string(), format!("{}: disk full", d.join("state.json.tmp").display()));
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        assert!(!d.join("state.json.tmp").exists());
        replace(&p, "new").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new");
    }

    #[test]
    fn an_error_names_the_file_and_says_its_cause_once() {
        let p = Path::new("/nonexistent/equiarm/x");
        let e = std::fs::read(p).map_err(at(p)).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with("/nonexistent/equiarm/x: "), "{text}");
        assert!(std::error::Error::source(&e).is_none());
        assert_eq!(replace(p, "x").unwrap_err().path, Path::new("/nonexistent/equiarm/x.tmp"));
    }
}
