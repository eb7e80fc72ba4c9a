//! Reading the files an operator names (the config file, the tokens file,
//! TLS certificates and keys, checkpoints): regular files only, each kind
//! with a size bound. A path may name a FIFO, whose open waits for a
//! writer (at start, for ever), or a device such as `/dev/zero`, which
//! never ends; neither is a file the server reads, and a wrong path must
//! fail fast with a message, never hang a start or fill memory.
//!
//! The file is opened without blocking (`O_NONBLOCK`: a FIFO's open
//! returns at once) and its type taken from the opened handle (`fstat`),
//! so a path swapped between a check and the open cannot slip a FIFO or
//! a device past the check. Reads stop one byte past the bound, so a file
//! that grows while read is still refused.

use std::fs::{File, OpenOptions};
use std::io::Read;
use std::path::Path;

/// Why a file was not read. Callers name the file and its flag.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// Opening or reading failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The path names something other than a regular file.
    #[error("is {kind}, not a regular file; name a regular file")]
    NotRegular {
        /// What it is ("a FIFO", "a character device", ...).
        kind: &'static str,
    },
    /// The file holds more than its kind's bound.
    #[error("holds more than {limit} bytes, the most this kind of file may hold")]
    TooLarge {
        /// The bound, bytes.
        limit: u64,
    },
}

/// The bytes of the regular file at `path` (a symbolic link to one is
/// followed), at most `limit` of them.
///
/// # Errors
/// [`FileError`]: unreadable, not a regular file, or over `limit`.
pub fn read_regular(path: &Path, limit: u64) -> Result<Vec<u8>, FileError> {
    let file = open_nonblocking(path)?;
    let metadata = file.metadata()?;
    if !metadata.is_file() {
        return Err(FileError::NotRegular {
            kind: kind(&metadata.file_type()),
        });
    }
    if metadata.len() > limit {
        return Err(FileError::TooLarge { limit });
    }
    let mut data = Vec::with_capacity(usize::try_from(metadata.len()).unwrap_or(0));
    file.take(limit.saturating_add(1)).read_to_end(&mut data)?;
    if data.len() as u64 > limit {
        return Err(FileError::TooLarge { limit });
    }
    Ok(data)
}

/// [`read_regular`] as UTF-8 text.
///
/// # Errors
/// As [`read_regular`], and bytes that are not UTF-8.
pub fn read_regular_text(path: &Path, limit: u64) -> Result<String, FileError> {
    String::from_utf8(read_regular(path, limit)?).map_err(|e| {
        FileError::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("is not UTF-8 text ({e})"),
        ))
    })
}

#[cfg(unix)]
fn open_nonblocking(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
}

#[cfg(not(unix))]
fn open_nonblocking(path: &Path) -> std::io::Result<File> {
    OpenOptions::new().read(true).open(path)
}

/// What a file that is not a regular one is, for the message.
fn kind(file_type: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if file_type.is_fifo() {
            return "a FIFO";
        }
        if file_type.is_char_device() {
            return "a character device";
        }
        if file_type.is_block_device() {
            return "a block device";
        }
        if file_type.is_socket() {
            return "a socket";
        }
    }
    if file_type.is_dir() {
        "a directory"
    } else {
        "no regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let dir =
            std::env::temp_dir().join(format!("meshless-files-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    #[test]
    fn regular_files_within_the_bound_are_read_and_others_refused() {
        let dir = dir("bound");
        let file = dir.join("ok");
        std::fs::write(&file, b"0123456789").expect("write");
        assert_eq!(read_regular(&file, 10).expect("fits"), b"0123456789");
        let err = read_regular(&file, 9).expect_err("over the bound");
        assert!(matches!(err, FileError::TooLarge { limit: 9 }), "{err}");
        let err = read_regular(&dir, 1 << 20).expect_err("a directory");
        assert!(err.to_string().contains("a directory"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `/dev/zero` reports no size and never ends: refused by its type,
    /// before a byte is read.
    #[cfg(unix)]
    #[test]
    fn a_device_is_refused_without_reading() {
        let err = read_regular(Path::new("/dev/zero"), 1 << 20).expect_err("a device");
        assert!(err.to_string().contains("character device"), "{err}");
    }
}
