//! A recorded SPAD-camera cube as labs keep it: one array of a MATLAB
//! (level 5 or v7.3) or NumPy file, its axes in any order, values of any
//! numeric type and sign (a subtracted background leaves negatives), and
//! the pixels' positions on the imaged face from a second file or a pitch.

use std::path::{Path, PathBuf};

use ndarray::{Array3, ArrayD, Axis, Ix2};
use serde::Serialize;

use crate::formats::lab_array::{self, LabArray};

/// The order of a cube's axes in its file: a permutation of `t` (time
/// bins), `y` (rows) and `x` (columns), e.g. `yxt` for MATLAB's rows x
/// columns x bins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Axes([u8; 3]);

impl Axes {
    /// Rows, columns, bins: the usual MATLAB layout.
    pub const MATLAB: Axes = Axes(*b"yxt");

    /// Parses `yxt`, `tyx`, ...
    pub fn parse(s: &str) -> Result<Self, String> {
        let b = s.as_bytes();
        let mut sorted = b.to_vec();
        sorted.sort_unstable();
        if sorted != b"txy" {
            return Err(format!(
                "axes `{s}`: name the file's three axes in order with t (bins), y (rows) and x (columns), e.g. yxt"
            ));
        }
        Ok(Axes([b[0], b[1], b[2]]))
    }

    /// Where each of t, y, x sits in the file's axes.
    fn positions(self) -> [usize; 3] {
        let at = |c| self.0.iter().position(|&a| a == c).expect("parsed");
        [at(b't'), at(b'y'), at(b'x')]
    }

    /// As written.
    pub fn name(self) -> String {
        String::from_utf8_lossy(&self.0).into_owned()
    }
}

/// Where the pixels sit on the imaged face.
#[derive(Debug, Clone)]
pub enum Positions {
    /// The same pitch for every pixel (cm): x (columns), y (rows).
    Pitch(f64, f64),
    /// Pixel centres from a file, in `unit_cm` per file unit; `names` picks
    /// the x and y arrays where the file holds several.
    File {
        /// The positions file.
        path: PathBuf,
        /// Centimetres per unit of the file's numbers.
        unit_cm: f64,
        /// Names of the x and y arrays, if the file holds other arrays.
        names: Option<(String, String)>,
    },
}

/// A cube read from a file.
#[derive(Debug, Clone)]
pub struct Cube {
    /// Values (bins, rows, columns) as recorded.
    pub values: Array3<f64>,
    /// Pixel pitch (cm): x (columns), y (rows).
    pub pitch_cm: (f64, f64),
    /// What was read, for the notes.
    pub provenance: Provenance,
}

/// How the cube was read.
#[derive(Debug, Clone, Serialize)]
pub struct Provenance {
    /// The cube's file.
    pub file: String,
    /// Its array.
    pub variable: String,
    /// Its axes in the file.
    pub axes: String,
    /// Where the pitch came from.
    pub pitch_from: String,
    /// The largest departure of a pixel centre from the regular grid, in
    /// pitches (0 for a stated pitch).
    pub grid_departure: f64,
}

/// Reads the cube `variable` (or the only 3-D array) of `path` with its
/// `axes`, and its pixel `positions`. The error names the file and field.
pub fn read(
    path: &Path,
    variable: Option<&str>,
    axes: Axes,
    positions: &Positions,
) -> Result<Cube, String> {
    let named = |e: String| format!("{}: {e}", path.display());
    let array =
        lab_array::pick(path, variable, "cube (a 3-D array)", |s| s.len() == 3).map_err(named)?;
    if array.values.ndim() != 3 {
        return Err(named(format!(
            "`{}` has shape {:?}: a cube is a 3-D array",
            array.name,
            array.values.shape()
        )));
    }
    let [t, y, x] = axes.positions();
    let values: Array3<f64> = array
        .values
        .view()
        .permuted_axes(vec![t, y, x])
        .into_dimensionality()
        .expect("3-D")
        .as_standard_layout()
        .into_owned();
    check_values(&values, &array.name).map_err(named)?;
    let (_, h, w) = values.dim();
    let (pitch_cm, pitch_from, grid_departure) = match positions {
        Positions::Pitch(px, py) => {
            if !(px.is_finite() && *px > 0.0 && py.is_finite() && *py > 0.0) {
                return Err(format!("pixel pitch {px} x {py} cm: both must be positive"));
            }
            ((*px, *py), "stated".to_string(), 0.0)
        }
        Positions::File {
            path: p,
            unit_cm,
            names,
        } => {
            let (pitch, departure) = pitch_from_positions(p, *unit_cm, names.as_ref(), (h, w))
                .map_err(|e| format!("{}: {e}", p.display()))?;
            (
                pitch,
                format!("pixel centres in {}", p.display()),
                departure,
            )
        }
    };
    Ok(Cube {
        values,
        pitch_cm,
        provenance: Provenance {
            file: path.display().to_string(),
            variable: array.name,
            axes: axes.name(),
            pitch_from,
            grid_departure,
        },
    })
}

/// A cube given as values (bins, rows, columns) with its pitch (x, y in
/// cm), e.g. from Python; `source` names it in the notes and errors.
pub fn from_values(
    values: Array3<f64>,
    pitch_cm: (f64, f64),
    source: &str,
) -> Result<Cube, String> {
    check_values(&values, "cube").map_err(|e| format!("{source}: {e}"))?;
    let (px, py) = pitch_cm;
    if !(px.is_finite() && px > 0.0 && py.is_finite() && py > 0.0) {
        return Err(format!("pixel pitch {px} x {py} cm: both must be positive"));
    }
    Ok(Cube {
        values,
        pitch_cm,
        provenance: Provenance {
            file: source.to_string(),
            variable: "cube".into(),
            axes: "tyx".into(),
            pitch_from: "stated".into(),
            grid_departure: 0.0,
        },
    })
}

/// Refuses a cube with a value that is not finite (named by its bin, row
/// and column), an empty one, or one with no positive value.
fn check_values(values: &Array3<f64>, name: &str) -> Result<(), String> {
    if let Some(((k, i, j), v)) = values.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(format!(
            "`{name}` holds {v} at bin {k}, row {i}, column {j}: a cube's values must be finite (mark bad pixels with a mask instead)"
        ));
    }
    let (bins, h, w) = values.dim();
    if bins == 0 || h == 0 || w == 0 {
        return Err(format!("`{name}` is empty: shape {:?}", values.dim()));
    }
    if values.iter().all(|&v| v <= 0.0) {
        return Err(format!(
            "`{name}` has no positive value: no light was recorded (or the background subtracted is all of it)"
        ));
    }
    Ok(())
}

/// The pitch (x, y in cm) of a cube of `shape` (rows, columns) from a file
/// of pixel centres: one array of (rows, columns, 2) or (2, rows,
/// columns), or two (rows, columns) arrays, or two vectors (columns' x,
/// rows' y). The x array is the one that changes along the columns. Also
/// the largest departure of a centre from the regular grid, in pitches.
fn pitch_from_positions(
    path: &Path,
    unit_cm: f64,
    names: Option<&(String, String)>,
    shape: (usize, usize),
) -> Result<((f64, f64), f64), String> {
    if !(unit_cm.is_finite() && unit_cm > 0.0) {
        return Err(format!("positions unit {unit_cm} cm: must be positive"));
    }
    let (arrays, _) = lab_array::read_all(path)?;
    let (h, w) = shape;
    let pick = |n: &str| {
        arrays
            .iter()
            .find(|a| a.name == n)
            .cloned()
            .ok_or_else(|| format!("no array `{n}`"))
    };
    let grids: Vec<ndarray::Array2<f64>> = if let Some((xn, yn)) = names {
        vec![
            as_grid(&pick(xn)?, shape, true)?,
            as_grid(&pick(yn)?, shape, false)?,
        ]
    } else if let Some(one) = arrays.iter().find(|a| {
        let s = a.values.shape();
        s == [h, w, 2] || s == [2, h, w]
    }) {
        let v = &one.values;
        let along = if v.shape()[0] == 2 && v.shape() != [h, w, 2] {
            0
        } else {
            2
        };
        (0..2)
            .map(|c| {
                v.index_axis(Axis(along), c)
                    .into_dimensionality::<Ix2>()
                    .expect("2-D")
                    .to_owned()
            })
            .collect()
    } else {
        let fitting: Vec<&LabArray> = arrays
            .iter()
            .filter(|a| {
                let s = a.values.shape();
                s == [h, w] || (a.values.len() == w || a.values.len() == h) && a.values.ndim() <= 2
            })
            .collect();
        if fitting.len() != 2 {
            return Err(format!(
                "no pixel centres for a cube of {h} x {w} pixels: the file holds {}; give one array of ({h}, {w}, 2) or two of ({h}, {w}) (name them with --positions-names X,Y)",
                arrays
                    .iter()
                    .map(|a| format!("{} {:?}", a.name, a.values.shape()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        vec![
            as_grid(fitting[0], shape, true)?,
            as_grid(fitting[1], shape, false)?,
        ]
    };
    // Which grid changes along the columns.
    let step = |g: &ndarray::Array2<f64>, axis: usize| -> f64 {
        let d = if axis == 1 {
            &g.slice(ndarray::s![.., 1..]) - &g.slice(ndarray::s![.., ..-1])
        } else {
            &g.slice(ndarray::s![1.., ..]) - &g.slice(ndarray::s![..-1, ..])
        };
        let mut v: Vec<f64> = d.iter().map(|x| x.abs()).collect();
        if v.is_empty() {
            return 0.0;
        }
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    if let Some(v) = grids.iter().flat_map(|g| g.iter()).find(|v| !v.is_finite()) {
        return Err(format!("a pixel centre is {v}"));
    }
    let (a, b) = (&grids[0], &grids[1]);
    let (x, y) = if step(a, 1) >= step(a, 0) {
        (a, b)
    } else {
        (b, a)
    };
    let (px, py) = (step(x, 1), step(y, 0));
    if w > 1 && px <= 0.0 || h > 1 && py <= 0.0 {
        return Err(format!(
            "the pixel centres do not change along the {}: they are not this cube's pixels",
            if px <= 0.0 { "columns" } else { "rows" }
        ));
    }
    let (px, py) = (if w > 1 { px } else { py }, if h > 1 { py } else { px });
    // Departure from the regular grid through the first centre.
    let mut worst: f64 = 0.0;
    for i in 0..h {
        for j in 0..w {
            let dx = (x[[i, j]] - x[[0, 0]]).abs() - j as f64 * px;
            let dy = (y[[i, j]] - y[[0, 0]]).abs() - i as f64 * py;
            worst = worst.max(dx.abs() / px).max(dy.abs() / py);
        }
    }
    if worst > 0.25 {
        return Err(format!(
            "the pixel centres depart from a regular grid of {px} x {py} by {worst:.2} pitches: not a camera's pixel grid"
        ));
    }
    Ok(((px * unit_cm, py * unit_cm), worst))
}

/// A positions array as a (rows, columns) grid: itself, or a vector
/// spread along the columns (`is_x`) or the rows.
fn as_grid(
    a: &LabArray,
    (h, w): (usize, usize),
    is_x: bool,
) -> Result<ndarray::Array2<f64>, String> {
    let v: &ArrayD<f64> = &a.values;
    if v.shape() == [h, w] {
        return Ok(v
            .view()
            .into_dimensionality::<Ix2>()
            .expect("2-D")
            .to_owned());
    }
    let flat: Vec<f64> = v.iter().copied().collect();
    match (is_x, flat.len()) {
        (true, n) if n == w => Ok(ndarray::Array2::from_shape_fn((h, w), |(_, j)| flat[j])),
        (false, n) if n == h => Ok(ndarray::Array2::from_shape_fn((h, w), |(i, _)| flat[i])),
        _ => Err(format!(
            "`{}` of shape {:?} does not match a cube of {h} x {w} pixels",
            a.name,
            v.shape()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_parse_and_refuse() {
        assert_eq!(Axes::parse("yxt").unwrap(), Axes::MATLAB);
        assert_eq!(Axes::parse("tyx").unwrap().positions(), [0, 1, 2]);
        assert!(Axes::parse("xyz").unwrap_err().contains("t (bins)"));
    }
}
