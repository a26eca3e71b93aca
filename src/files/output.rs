//! Outputs written whole or not at all. An [`AtomicFile`] is written under
//! a hidden temporary name in its destination folder
//! (`.NAME.partial-PID-N`), and [`AtomicFile::commit`] flushes it to disk
//! and renames it into place: a reader of `NAME` sees the old file or the
//! complete new one, never a part. A derived output dropped before its
//! commit (an error, a panic) is removed; a recording's is kept under its
//! temporary name, since what it holds was read from a device once.
//!
//! Before a byte is written, the destination is compared by identity with
//! every file this process has read ([`super::input`]), and refused if it
//! is one of them or exists as something other than a regular file (a
//! rename would replace a device node or a FIFO).

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::input::{FileId, input_with_id};

/// Counter that makes temporary names unique within the process.
static NEXT: AtomicU64 = AtomicU64::new(0);

/// Temporaries of derived outputs being written now, removed by
/// [`remove_unfinished`] when the process is ended by a signal.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes the temporaries of every derived output still being written
/// (recordings are kept): for a signal handler that ends the process.
pub fn remove_unfinished() {
    for tmp in live().drain(..) {
        let _ = std::fs::remove_file(tmp);
    }
}

/// The marker in every temporary name: a file whose name holds it is an
/// unfinished output.
pub const PARTIAL_MARKER: &str = ".partial-";

/// Whether `path` names an unfinished output (a temporary left by a
/// process that was killed).
pub fn is_partial_name(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with('.') && n.contains(PARTIAL_MARKER))
}

/// Refuses `dest` as an output when it is (by identity) a file this
/// process has read, or exists as anything but a regular file.
pub fn check_destination(dest: &Path) -> io::Result<()> {
    let Ok(meta) = std::fs::metadata(dest) else {
        return Ok(());
    };
    if let Some(input) = input_with_id(FileId::of(&meta)) {
        let same = if input == dest {
            String::new()
        } else {
            format!(" (read as {})", input.display())
        };
        return Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "{} is an input of this command{same}; refusing to write over it (name another output)",
                dest.display()
            ),
        ));
    }
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{} exists and is not a regular file ({}); outputs are renamed into place, so name a regular file",
                dest.display(),
                crate::files::input::file_kind(&meta)
            ),
        ));
    }
    Ok(())
}

/// How a recording's writing ended; the file says which.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Completion {
    /// The run reached its planned end: everything meant to be written is there.
    Complete,
    /// The run ended early (Ctrl-C, SIGTERM, a device error): every record
    /// read is there and counted, and the file says the run was cut.
    Interrupted,
}

/// A file being written under a temporary name, renamed into place on
/// [`AtomicFile::commit`].
#[derive(Debug)]
pub struct AtomicFile {
    file: Option<File>,
    tmp: PathBuf,
    dest: PathBuf,
    keep_on_drop: bool,
    renamed: bool,
}

impl AtomicFile {
    /// Starts a derived output (a stack, a report): removed if dropped
    /// before [`Self::commit`].
    pub fn create(dest: &Path) -> io::Result<Self> {
        Self::open(dest, false)
    }

    /// Starts a recording (photons read once from a device): if dropped
    /// before [`Self::commit`], kept under its temporary name, which says
    /// it is unfinished.
    pub fn create_recording(dest: &Path) -> io::Result<Self> {
        Self::open(dest, true)
    }

    fn open(dest: &Path, keep_on_drop: bool) -> io::Result<Self> {
        check_destination(dest)?;
        let name = dest.file_name().ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{}: not a file name", dest.display()),
            )
        })?;
        let dir = folder(dest);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(
            ".{}{PARTIAL_MARKER}{}-{n}",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = std::fs::OpenOptions::new()
            .write(true)
            .read(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| {
                io::Error::new(
                    e.kind(),
                    format!("cannot create a file in the folder {}: {e}", dir.display()),
                )
            })?;
        if !keep_on_drop {
            live().push(tmp.clone());
        }
        Ok(Self {
            file: Some(file),
            tmp,
            dest: dest.to_path_buf(),
            keep_on_drop,
            renamed: false,
        })
    }

    /// The final path.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// The temporary path, where the bytes are until the commit.
    pub fn temporary(&self) -> &Path {
        &self.tmp
    }

    fn file(&mut self) -> &mut File {
        self.file
            .as_mut()
            .expect("an AtomicFile is open until commit")
    }

    /// Renames the file to its destination, which is checked again (it may
    /// have appeared since the start). A recording is synced to disk first,
    /// and the rename after it, so that a power cut cannot lose it; a
    /// derived output (which can be made again) is only renamed, which
    /// already keeps readers from seeing a part of it.
    pub fn commit(mut self) -> io::Result<PathBuf> {
        let file = self.file.take().expect("committed once");
        if self.keep_on_drop {
            file.sync_all()?;
        }
        drop(file);
        check_destination(&self.dest)?;
        std::fs::rename(&self.tmp, &self.dest)?;
        self.forget();
        if self.keep_on_drop {
            File::open(folder(&self.dest))?.sync_all()?;
        }
        self.renamed = true;
        Ok(self.dest.clone())
    }
}

impl AtomicFile {
    fn forget(&self) {
        live().retain(|p| p != &self.tmp);
    }

    /// Flushes `out`'s buffer and commits the file under it ([`Self::commit`]).
    pub fn commit_buffered(out: io::BufWriter<Self>) -> io::Result<PathBuf> {
        out.into_inner().map_err(|e| e.into_error())?.commit()
    }
}

/// The folder `dest` goes in (`.` for a bare file name).
fn folder(dest: &Path) -> &Path {
    match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file().write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.file().write_all(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file().flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        self.file().seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.renamed && !self.keep_on_drop {
            let _ = std::fs::remove_file(&self.tmp);
            self.forget();
        }
    }
}

/// Writes `bytes` to `dest` whole or not at all.
pub fn write_atomic(dest: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    let mut f = AtomicFile::create(dest.as_ref())?;
    f.write_all(bytes.as_ref())?;
    f.commit().map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::open_input;

    #[test]
    fn a_file_appears_whole_only_at_commit() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out.bin");
        std::fs::write(&dest, b"old").unwrap();
        let mut f = AtomicFile::create(&dest).unwrap();
        f.write_all(b"new contents").unwrap();
        assert_eq!(std::fs::read(&dest).unwrap(), b"old");
        assert!(is_partial_name(f.temporary()));
        f.commit().unwrap();
        assert_eq!(std::fs::read(&dest).unwrap(), b"new contents");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_dropped_output_leaves_nothing_and_a_dropped_recording_its_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let mut f = AtomicFile::create(&dir.path().join("a")).unwrap();
        f.write_all(b"x").unwrap();
        drop(f);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let mut r = AtomicFile::create_recording(&dir.path().join("r.ptu")).unwrap();
        r.write_all(b"photons").unwrap();
        let tmp = r.temporary().to_path_buf();
        drop(r);
        assert_eq!(std::fs::read(&tmp).unwrap(), b"photons");
        assert!(!dir.path().join("r.ptu").exists());
    }

    #[test]
    fn an_input_is_refused_by_every_spelling() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("rec.ptu");
        std::fs::write(&input, b"recording").unwrap();
        crate::files::input::remember_inputs();
        open_input(&input, "PTU file").unwrap();
        let hard = dir.path().join("hard.ptu");
        std::fs::hard_link(&input, &hard).unwrap();
        let soft = dir.path().join("soft.ptu");
        #[cfg(unix)]
        std::os::unix::fs::symlink(&input, &soft).unwrap();
        let dotted = dir.path().join(".").join("rec.ptu");
        for dest in [&input, &hard, &soft, &dotted] {
            let err = write_atomic(dest, b"over").unwrap_err().to_string();
            assert!(err.contains("is an input of this command"), "{err}");
        }
        assert_eq!(std::fs::read(&input).unwrap(), b"recording");
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_not_replaced() {
        let err = AtomicFile::create(Path::new("/dev/null"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a regular file"), "{err}");
    }
}
