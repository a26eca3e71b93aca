//! Every file a command will read and write, checked together before it
//! starts: no two outputs are the same file and no output is an input, by
//! identity (an existing file by device and inode, however its path is
//! spelled; a new one by its folder's real path and its name), and every
//! output can be created and renamed into place. A command that acquires
//! for minutes learns of a bad output path before the device is opened,
//! not when the first byte is written.

use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::input::FileId;

/// Where a path leads: an existing file, or a name that does not exist yet
/// in a real folder.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Location {
    Existing(FileId),
    New(PathBuf),
}

/// `path` with `.` dropped and `..` applied, component by component.
fn lexical(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other),
        }
    }
    out
}

/// The nearest ancestor of `path` that exists (the current folder for a
/// bare relative name).
fn existing_ancestor(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut at = lexical(&absolute);
    while !at.as_os_str().is_empty() && std::fs::symlink_metadata(&at).is_err() {
        if !at.pop() {
            break;
        }
    }
    at
}

/// Where `path` leads.
fn locate(path: &Path) -> Location {
    match FileId::at(path) {
        Some(id) => Location::Existing(id),
        None => Location::New(new_location(path)),
    }
}

/// `path` as the real path of its nearest existing ancestor and the rest of
/// its components.
fn new_location(path: &Path) -> PathBuf {
    let absolute = lexical(&std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf()));
    let base = existing_ancestor(&absolute);
    let rest = absolute.strip_prefix(&base).unwrap_or(Path::new(""));
    let real = std::fs::canonicalize(&base).unwrap_or(base.clone());
    real.join(rest)
}

/// Why the files of a command cannot be used as named.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// Two outputs are one file.
    #[error(
        "the {first} {first_path} and the {second} {second_path} are the same file: each output needs a file of its own, or one would replace the other"
    )]
    SameOutput {
        /// What the first is (e.g. "PTU recording").
        first: String,
        /// Its path as given.
        first_path: PathBuf,
        /// What the second is.
        second: String,
        /// Its path as given.
        second_path: PathBuf,
    },
    /// An output is an input.
    #[error(
        "the {output} {output_path} is {input_path}, the {input}: refusing to write over an input (name another output)"
    )]
    OutputIsInput {
        /// What the output is.
        output: String,
        /// Its path as given.
        output_path: PathBuf,
        /// What the input is.
        input: String,
        /// Its path as given.
        input_path: PathBuf,
    },
    /// An output cannot be created where it is named.
    #[error("the {what} {path} cannot be written: {reason}")]
    Unwritable {
        /// What the output is.
        what: String,
        /// Its path as given.
        path: PathBuf,
        /// Why, in words.
        reason: String,
    },
}

impl PlanError {
    /// What the output in question is (the role its caller gave it).
    pub fn output_role(&self) -> &str {
        match self {
            Self::SameOutput { second, .. } => second,
            Self::OutputIsInput { output, .. } => output,
            Self::Unwritable { what, .. } => what,
        }
    }
}

/// The files of one run: what it reads and what it writes, each with what
/// it is, in words ("PTU recording", "tag file", "stack").
#[derive(Debug, Clone, Default)]
pub struct FilePlan {
    inputs: Vec<(String, PathBuf)>,
    outputs: Vec<(String, PathBuf)>,
    folders: Vec<PathBuf>,
}

/// Counter that keeps probe names apart within the process.
static PROBE: AtomicU64 = AtomicU64::new(0);

impl FilePlan {
    /// No files yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A file the run reads.
    pub fn input(&mut self, what: impl Into<String>, path: &Path) -> &mut Self {
        self.inputs.push((what.into(), path.to_path_buf()));
        self
    }

    /// A file the run writes.
    pub fn output(&mut self, what: impl Into<String>, path: &Path) -> &mut Self {
        self.outputs.push((what.into(), path.to_path_buf()));
        self
    }

    /// A folder the run makes when it is missing (an output folder): an
    /// output may go in it, or below it, before it exists. Any other
    /// output's folder must exist.
    pub fn folder(&mut self, path: &Path) -> &mut Self {
        self.folders.push(path.to_path_buf());
        self
    }

    /// Checks every output against every other and every input (by
    /// identity), against the files this process has already read, and
    /// that it can be created and renamed into place (its folder is one,
    /// or can be made, and takes a new file). Writes nothing that stays.
    pub fn check(&self) -> Result<(), PlanError> {
        let inputs: Vec<Location> = self.inputs.iter().map(|(_, p)| locate(p)).collect();
        // The locations of the outputs checked so far, in order.
        let mut seen: Vec<Location> = Vec::new();
        for (what, path) in &self.outputs {
            let here = locate(path);
            if let Some(j) = seen.iter().position(|l| *l == here) {
                let (first, first_path) = &self.outputs[j];
                return Err(PlanError::SameOutput {
                    first: first.clone(),
                    first_path: first_path.clone(),
                    second: what.clone(),
                    second_path: path.clone(),
                });
            }
            if let Some(k) = inputs.iter().position(|l| *l == here) {
                let (input, input_path) = &self.inputs[k];
                return Err(PlanError::OutputIsInput {
                    output: what.clone(),
                    output_path: path.clone(),
                    input: input.clone(),
                    input_path: input_path.clone(),
                });
            }
            writable(path, &self.folders).map_err(|reason| PlanError::Unwritable {
                what: what.clone(),
                path: path.clone(),
                reason,
            })?;
            seen.push(here);
        }
        Ok(())
    }
}

/// Whether a file can be written at `path` as outputs are (a temporary in
/// its folder, renamed into place): an existing `path` must be a regular
/// file that is not an input of this process; its folder must exist or be
/// (or lie in) one of `made` (the folders the run makes); and the nearest
/// folder that exists must take a new file (tried with an empty probe,
/// removed at once).
fn writable(path: &Path, made: &[PathBuf]) -> Result<(), String> {
    if path.file_name().is_none() {
        return Err("it names a folder, not a file".into());
    }
    super::output::check_destination(path).map_err(|e| e.to_string())?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if std::fs::symlink_metadata(parent).is_err() {
        let wanted = new_location(parent);
        if !made.iter().any(|m| wanted.starts_with(new_location(m))) {
            return Err(format!(
                "its folder {} does not exist (only the output folder is made)",
                parent.display()
            ));
        }
    }
    let folder = existing_ancestor(parent);
    let folder = if folder.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        folder
    };
    match std::fs::metadata(&folder) {
        Ok(m) if m.is_dir() => {}
        Ok(m) => {
            return Err(format!(
                "{} is not a folder ({})",
                folder.display(),
                super::input::file_kind(&m)
            ));
        }
        Err(e) => return Err(format!("{}: {e}", folder.display())),
    }
    let probe = folder.join(format!(
        ".scatterscope-probe-{}-{}",
        std::process::id(),
        PROBE.fetch_add(1, Ordering::Relaxed)
    ));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(format!(
            "no file can be created in the folder {}: {e}",
            folder.display()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_spellings_of_one_new_file_are_one_output() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("x.ptu");
        let b = dir.path().join(".").join("sub").join("..").join("x.ptu");
        let err = FilePlan::new()
            .output("PTU recording", &a)
            .output("tag file", &b)
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("are the same file"), "{err}");
        assert!(
            err.contains("PTU recording") && err.contains("tag file"),
            "{err}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn an_existing_file_is_one_output_through_a_link() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("x.ptu");
        std::fs::write(&a, b"old").unwrap();
        let link = dir.path().join("y.ptu");
        std::fs::hard_link(&a, &link).unwrap();
        let err = FilePlan::new()
            .output("PTU recording", &a)
            .output("tag file", &link)
            .check()
            .unwrap_err();
        assert!(matches!(err, PlanError::SameOutput { .. }), "{err}");
    }

    #[test]
    fn an_output_that_is_an_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("rec.ptu");
        std::fs::write(&rec, b"recording").unwrap();
        let err = FilePlan::new()
            .input("recording replayed", &rec)
            .output("PTU recording", &dir.path().join("./rec.ptu"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains(", the recording replayed: refusing"), "{err}");
        assert_eq!(std::fs::read(&rec).unwrap(), b"recording");
    }

    #[test]
    fn outputs_in_a_folder_to_be_made_pass_and_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        FilePlan::new()
            .folder(&dir.path().join("a"))
            .output("stack", &dir.path().join("a/b/stack.exr"))
            .output("PTU recording", &dir.path().join("a/rec.ptu"))
            .check()
            .unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let err = FilePlan::new()
            .folder(&dir.path().join("a"))
            .output("PTU recording", &dir.path().join("elsewhere/rec.ptu"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("elsewhere does not exist"), "{err}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_folder_that_takes_no_file_is_named() {
        let err = FilePlan::new()
            .output("PTU recording", Path::new("/proc/x.ptu"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("/proc"), "{err}");
        let err = FilePlan::new()
            .folder(Path::new("/dev/null"))
            .output("stack", Path::new("/dev/null/x.exr"))
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a folder"), "{err}");
    }

    #[test]
    fn a_folder_is_not_an_output_file() {
        let dir = tempfile::tempdir().unwrap();
        let err = FilePlan::new()
            .output("tag file", dir.path())
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("is not a regular file (a directory)"), "{err}");
    }
}
