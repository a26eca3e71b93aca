//! How the library touches the file system: every file input passes one
//! gate ([`input`]: regular files only, opened without blocking, their
//! identity remembered), and every output is written whole or not at all
//! ([`output`]: a temporary name in the destination folder, then a rename),
//! never over a file the process has read; a run that names several files
//! checks them together before it starts ([`plan`]).

pub mod input;
pub mod output;
pub mod plan;

pub use input::{FileId, ReadError, open_input, open_regular, read_bounded};
pub use output::{AtomicFile, Completion, write_atomic};
pub use plan::{FilePlan, PlanError};
