//! The one gate for file inputs. [`open_input`] opens without blocking
//! (a FIFO with no writer, a device or a folder is refused at once, not
//! waited on) and requires a regular file. In a process that runs one
//! command (the CLI calls [`remember_inputs`]) it also records each
//! input's identity (device and inode, after links), so that
//! [`super::output`] refuses to write over anything the command has read,
//! however its path is spelled (relative, absolute, through a symbolic or a
//! hard link). A library user (a notebook that loads a stack, changes it
//! and saves it back) is not held to that; [`same_file`] serves the
//! functions that read and write at once. [`read_bounded`] reads such a
//! file whole, with a cap on its size.

use std::collections::HashMap;
use std::fs::{File, Metadata};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A file's identity: the device and inode it lives at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FileId {
    dev: u64,
    ino: u64,
}

impl FileId {
    /// The identity of the file `meta` describes.
    pub fn of(meta: &Metadata) -> Self {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            Self {
                dev: meta.dev(),
                ino: meta.ino(),
            }
        }
        #[cfg(not(unix))]
        {
            let _ = meta;
            Self { dev: 0, ino: 0 }
        }
    }

    /// The identity of the file at `path` (links followed), if it exists.
    pub fn at(path: &Path) -> Option<Self> {
        std::fs::metadata(path).ok().map(|m| Self::of(&m))
    }
}

/// Files read by this process, by identity, with the path they were read
/// as; `None` until [`remember_inputs`].
static INPUTS: Mutex<Option<HashMap<FileId, PathBuf>>> = Mutex::new(None);

fn inputs() -> std::sync::MutexGuard<'static, Option<HashMap<FileId, PathBuf>>> {
    INPUTS.lock().unwrap_or_else(|e| e.into_inner())
}

/// From now on, every input is remembered and no output may replace one:
/// for a process that runs one command.
pub fn remember_inputs() {
    inputs().get_or_insert_with(HashMap::new);
}

/// Whether `a` and `b` are the same existing file (links followed).
pub fn same_file(a: &Path, b: &Path) -> bool {
    matches!((FileId::at(a), FileId::at(b)), (Some(x), Some(y)) if x == y)
}

/// Remembers `path` (described by `meta`) as an input of this process,
/// when inputs are remembered.
fn register_input(path: &Path, meta: &Metadata) {
    if cfg!(not(unix)) {
        return;
    }
    if let Some(map) = inputs().as_mut() {
        map.entry(FileId::of(meta))
            .or_insert_with(|| path.to_path_buf());
    }
}

/// The path an input with identity `id` was read as, if this process
/// remembers reading it.
pub fn input_with_id(id: FileId) -> Option<PathBuf> {
    inputs().as_ref().and_then(|m| m.get(&id).cloned())
}

/// Opens `path` for reading without blocking: a FIFO opened for reading
/// waits for a writer and a device may wait too, so O_NONBLOCK makes the
/// open return at once, and the type is then checked on the open file (no
/// window between a check and the open). On a regular file the flag
/// changes nothing.
fn open_nonblocking(path: &Path) -> std::io::Result<(File, Metadata)> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    Ok((file, meta))
}

/// Opens `path` for reading as a `what` ("PTU file", "manifest"): without
/// blocking, refusing anything but a regular file, and remembering it as an
/// input. Returns the file and its metadata.
pub fn open_input(path: &Path, what: &'static str) -> Result<(File, Metadata), ReadError> {
    let (file, meta) = open_nonblocking(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    require_regular_file(path, &meta, what)?;
    register_input(path, &meta);
    Ok((file, meta))
}

/// [`open_input`] for readers with their own error types: a special file
/// is an `InvalidInput` error saying what it is (the caller names the path).
pub fn open_regular(path: &Path, what: &'static str) -> std::io::Result<(File, Metadata)> {
    let (file, meta) = open_nonblocking(path)?;
    if !meta.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "not a regular file ({}); a {what} must be one",
                file_kind(&meta)
            ),
        ));
    }
    register_input(path, &meta);
    Ok((file, meta))
}

/// Why a whole-file read was refused.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file cannot be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not a regular file (a device, a FIFO, a directory).
    #[error("{path}: not a regular file ({kind}); a {what} must be one")]
    NotAFile {
        /// The file.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
        /// What was expected.
        what: &'static str,
    },
    /// Larger than such a file may be.
    #[error("{path}: {} is more than a {what} may hold ({})", crate::memory::size(*len), crate::memory::size(*max))]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size (at least), bytes.
        len: u64,
        /// The cap, bytes.
        max: u64,
        /// What it was read as.
        what: &'static str,
    },
    /// The cap exceeds the memory budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

/// Refuses what `meta` describes unless it is a regular file: a device,
/// FIFO or folder at `path` would hang or fail a reader that expects a
/// `what`.
pub fn require_regular_file(
    path: &Path,
    meta: &std::fs::Metadata,
    what: &'static str,
) -> Result<(), ReadError> {
    if meta.is_file() {
        return Ok(());
    }
    Err(ReadError::NotAFile {
        path: path.to_path_buf(),
        kind: file_kind(meta),
        what,
    })
}

/// Reads the regular file at `path` whole, refusing special files and
/// files over `max` bytes (or over the budget); a file that grows past
/// the cap while it is read is refused too. `what` names the file's role
/// in errors ("configuration file").
pub fn read_bounded(path: &Path, max: u64, what: &'static str) -> Result<Vec<u8>, ReadError> {
    let io = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let (file, meta) = open_input(path, what)?;
    let too_large = |len| ReadError::TooLarge {
        path: path.to_path_buf(),
        len,
        max,
        what,
    };
    if meta.len() > max {
        return Err(too_large(meta.len()));
    }
    crate::memory::check(meta.len(), || format!("reading {}", path.display()))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > max {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// What kind of file `meta` describes, in words.
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_file() {
        return "regular file";
    }
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "a special file"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_fifo_with_no_writer_is_refused_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success());
        let t = std::time::Instant::now();
        let err = open_input(&fifo, "PTU file").unwrap_err().to_string();
        assert!(t.elapsed().as_secs_f64() < 1.0);
        assert!(err.contains("FIFO") && err.contains("pipe"), "{err}");
    }

    #[test]
    fn a_folder_is_refused_and_a_file_remembered() {
        let dir = tempfile::tempdir().unwrap();
        let err = open_input(dir.path(), "stack").unwrap_err().to_string();
        assert!(err.contains("directory"), "{err}");
        let file = dir.path().join("a.bin");
        std::fs::write(&file, b"x").unwrap();
        let link = dir.path().join("b.bin");
        std::fs::hard_link(&file, &link).unwrap();
        open_input(&file, "stack").unwrap();
        assert_eq!(input_with_id(FileId::at(&link).unwrap()), None);
        assert!(same_file(&file, &link));
        remember_inputs();
        open_input(&file, "stack").unwrap();
        assert_eq!(
            input_with_id(FileId::at(&link).unwrap()).as_deref(),
            Some(file.as_path())
        );
    }
}
