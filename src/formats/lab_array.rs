//! Named numeric arrays from the files labs keep them in: MATLAB level 5
//! ([`super::mat5`]) and v7.3 ([`super::mat`]) MAT-files, and `.npy`, each
//! in its own terms: a MAT-file's arrays in MATLAB's dimensions (rows
//! first), an `.npy` array in NumPy's shape. Errors are messages without
//! the path; callers name the file.

use std::path::Path;

use ndarray::{ArrayD, IxDyn, ShapeBuilder};

use super::detect::Format;

/// One array of a file.
#[derive(Debug, Clone)]
pub struct LabArray {
    /// The variable's name (an `.npy` file's is its file stem).
    pub name: String,
    /// The values in the file's logical dimensions.
    pub values: ArrayD<f64>,
}

/// Every numeric array of `path`, and `name (class)` of each variable
/// that is not one.
pub fn read_all(path: &Path) -> Result<(Vec<LabArray>, Vec<String>), String> {
    match Format::of_file(path) {
        Format::Npy => {
            let values = super::npy::read_numbers(path).map_err(|e| e.to_string())?;
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            Ok((vec![LabArray { name, values }], Vec::new()))
        }
        Format::Mat if is_level5(path) => {
            let contents = super::mat5::read(path)?;
            let arrays = contents
                .arrays
                .into_iter()
                .map(|a| {
                    let values = ArrayD::from_shape_vec(IxDyn(&a.dims).f(), a.values)
                        .expect("dimensions checked against the values");
                    LabArray {
                        name: a.name,
                        values: values.as_standard_layout().into_owned(),
                    }
                })
                .collect();
            Ok((arrays, contents.skipped))
        }
        Format::Mat => {
            let file = super::mat::open(path)?;
            let names = file
                .root_group()
                .and_then(|g| g.member_names())
                .map(|(_, d)| d)
                .map_err(|e| format!("its datasets cannot be listed: {e}"))?;
            let mut arrays = Vec::new();
            let mut skipped = Vec::new();
            for name in names {
                let ds = super::mat::dataset(&file, &name)?;
                match super::mat::numbers(&file, &ds) {
                    Ok(values) => {
                        // HDF5 stores MATLAB's column-major array under its
                        // dimensions reversed.
                        let shape: Vec<usize> = ds.shape().iter().map(|&d| d as usize).collect();
                        let values = ArrayD::from_shape_vec(IxDyn(&shape), values)
                            .map_err(|e| format!("dataset `{name}`: {e}"))?
                            .reversed_axes();
                        arrays.push(LabArray {
                            name,
                            values: values.as_standard_layout().into_owned(),
                        });
                    }
                    Err(e) => skipped.push(format!("{name} ({e})")),
                }
            }
            Ok((arrays, skipped))
        }
        other => Err(format!(
            "a {other:?} file holds no named arrays: give a MATLAB (.mat, level 5 or v7.3) or NumPy (.npy) file"
        )),
    }
}

/// The array of `path` named `name`, or else the only one whose shape
/// `fits`; the error lists what the file holds. `what` names the array
/// sought (`cube`, `pixel positions`, ...).
pub fn pick(
    path: &Path,
    name: Option<&str>,
    what: &str,
    fits: impl Fn(&[usize]) -> bool,
) -> Result<LabArray, String> {
    let (arrays, skipped) = read_all(path)?;
    let listing = || {
        let mut all: Vec<String> = arrays
            .iter()
            .map(|a| format!("{} {:?}", a.name, a.values.shape()))
            .collect();
        all.extend(skipped.iter().cloned());
        if all.is_empty() {
            "none".to_string()
        } else {
            all.join(", ")
        }
    };
    if let Some(name) = name {
        return arrays
            .iter()
            .find(|a| a.name == name)
            .cloned()
            .ok_or_else(|| {
                format!(
                    "no numeric array `{name}` (arrays in the file: {})",
                    listing()
                )
            });
    }
    let fitting: Vec<&LabArray> = arrays.iter().filter(|a| fits(a.values.shape())).collect();
    match fitting.as_slice() {
        [one] => Ok((*one).clone()),
        [] => Err(format!(
            "no array fits a {what} (arrays in the file: {})",
            listing()
        )),
        many => Err(format!(
            "{} arrays fit a {what} ({}): name one",
            many.len(),
            many.iter()
                .map(|a| a.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Whether `path` opens with a MATLAB level 5 header.
fn is_level5(path: &Path) -> bool {
    let mut head = [0u8; 128];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
        .is_ok()
        && super::mat5::is_level5(&head)
}
