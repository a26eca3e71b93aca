//! The object inside the medium as asked for on the command line (or from
//! code): the files, the geometry, the settings, with units on every
//! length and time. `scatterscope embedded` and `scatterscope
//! simulate-embedded` are these fields, their docs the flags' help.

use std::path::{Path, PathBuf};

use ndarray::Array2;
use scatterscope_physics::IrfTable;

use super::cube::{Axes, Positions};
use super::geometry::{Beam, Geometry};
use super::noise::Subtracted;
use super::simulate::{Recording, Target};
use super::{Outcome, Settings};
use crate::formats::detect::Format;
use crate::formats::lab_array;

/// Both slabs and the beam.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct GeometryArgs {
    /// Thickness of the slab between the beam and the object, with its
    /// unit (e.g. 2.5cm).
    #[cfg_attr(feature = "cli", arg(long = "front-thickness", value_name = "LENGTH", value_parser = crate::units::parse_positive_cm))]
    pub front_thickness_cm: f64,
    /// Thickness of the slab between the object and the imaged face.
    #[cfg_attr(feature = "cli", arg(long = "back-thickness", value_name = "LENGTH", value_parser = crate::units::parse_positive_cm))]
    pub back_thickness_cm: f64,
    /// Reduced scattering coefficient mu_s' of both slabs (1/cm).
    #[cfg_attr(feature = "cli", arg(long = "mu-s-reduced", value_name = "PER_CM"))]
    pub mu_s_reduced_per_cm: f64,
    /// Absorption coefficient mu_a of both slabs (1/cm).
    #[cfg_attr(feature = "cli", arg(long = "mu-a", value_name = "PER_CM"))]
    pub mu_a_per_cm: f64,
    /// Refractive index of both slabs.
    #[cfg_attr(feature = "cli", arg(long = "index", value_name = "N"))]
    pub refractive_index: f64,
    /// The back slab's mu_s' where it differs from the front's (1/cm).
    #[cfg_attr(
        feature = "cli",
        arg(long = "back-mu-s-reduced", value_name = "PER_CM")
    )]
    pub back_mu_s_reduced_per_cm: Option<f64>,
    /// The back slab's mu_a where it differs from the front's (1/cm).
    #[cfg_attr(feature = "cli", arg(long = "back-mu-a", value_name = "PER_CM"))]
    pub back_mu_a_per_cm: Option<f64>,
    /// The beam entering the front slab: `plane`, or a Gaussian's full
    /// width at half maximum with its unit (e.g. 6cm).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "plane|LENGTH", default_value = "plane")
    )]
    pub beam: String,
    /// The Gaussian beam's centre from the imaged field's centre, x
    /// (columns) and y (rows), with units (e.g. 0.5cm,-2mm).
    #[cfg_attr(
        feature = "cli",
        arg(long = "beam-centre", value_name = "X,Y", default_value = "0cm,0cm")
    )]
    pub beam_centre: String,
}

impl GeometryArgs {
    /// The geometry, with `irf` as the instrument's response.
    pub fn geometry(&self, irf: Option<IrfTable>) -> Result<Geometry, String> {
        let front = super::geometry::slab(
            self.mu_s_reduced_per_cm,
            self.mu_a_per_cm,
            self.refractive_index,
            self.front_thickness_cm,
        );
        let back = super::geometry::slab(
            self.back_mu_s_reduced_per_cm
                .unwrap_or(self.mu_s_reduced_per_cm),
            self.back_mu_a_per_cm.unwrap_or(self.mu_a_per_cm),
            self.refractive_index,
            self.back_thickness_cm,
        );
        let beam = if self.beam == "plane" {
            Beam::Plane
        } else {
            let fwhm_cm = crate::units::parse_positive_cm(&self.beam)
                .map_err(|e| format!("--beam: {e} (or `plane`)"))?;
            let centre_cm =
                pair_cm(&self.beam_centre).map_err(|e| format!("--beam-centre: {e}"))?;
            Beam::Gaussian { fwhm_cm, centre_cm }
        };
        let g = Geometry {
            front,
            back,
            beam,
            irf,
        };
        g.validate().map_err(|e| e.to_string())?;
        Ok(g)
    }
}

/// Two lengths `A,B` with units, in cm.
fn pair_cm(text: &str) -> Result<(f64, f64), String> {
    let (a, b) = text
        .split_once(',')
        .ok_or_else(|| format!("`{text}`: two lengths separated by a comma"))?;
    let parse = |t: &str| crate::units::parse_cm(t.trim(), crate::units::BareNumber::Refused);
    Ok((parse(a)?, parse(b)?))
}

/// A recorded cube to reconstruct.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct EmbeddedRequest {
    /// The cube: a MATLAB file (level 5 or v7.3) or a NumPy .npy file.
    pub cube: PathBuf,
    /// The cube's array in its file (default: the file's only 3-D array).
    #[cfg_attr(feature = "cli", arg(long, value_name = "NAME"))]
    pub variable: Option<String>,
    /// The cube's axes in the file's order: t (bins), y (rows), x
    /// (columns). Default yxt for MATLAB files, tyx for .npy.
    #[cfg_attr(feature = "cli", arg(long, value_name = "ORDER"))]
    pub axes: Option<String>,
    /// Width of the cube's time bins, with its unit (default ps; e.g.
    /// 50ps).
    #[cfg_attr(feature = "cli", arg(long = "bin-width", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub bin_width_ps: f64,
    /// A file of the pixels' centres on the imaged face (MATLAB or .npy:
    /// one (rows, cols, 2) array, or two (rows, cols) arrays or vectors).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "FILE", conflicts_with = "pitch")
    )]
    pub positions: Option<PathBuf>,
    /// The length one unit of the positions file is (e.g. 1mm, 1cm, 1m).
    #[cfg_attr(feature = "cli", arg(long = "positions-unit", value_name = "LENGTH", requires = "positions", value_parser = crate::units::parse_positive_cm))]
    pub positions_unit_cm: Option<f64>,
    /// The names of the x and y arrays in the positions file, where it
    /// holds others too (e.g. xpos,ypos).
    #[cfg_attr(
        feature = "cli",
        arg(long = "positions-names", value_name = "X,Y", requires = "positions")
    )]
    pub positions_names: Option<String>,
    /// The pixel pitch on the imaged face instead of a positions file:
    /// one length (square pixels) or X,Y (e.g. 1.4mm or 1.43mm,1.39mm).
    #[cfg_attr(feature = "cli", arg(long, value_name = "LENGTH[,LENGTH]"))]
    pub pitch: Option<String>,
    /// Both slabs and the beam.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub geometry: GeometryArgs,
    /// The pulse's entry into the front slab on the cube's clock (after
    /// bin 0's start), with its unit; fitted to the cube's time profile
    /// when not given.
    #[cfg_attr(feature = "cli", arg(long = "time-zero", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub time_zero_ps: Option<f64>,
    /// Also fit both slabs' reduced scattering (one factor) to the cube's
    /// time profile, and use it.
    #[cfg_attr(feature = "cli", arg(long = "fit-scattering"))]
    pub fit_scattering: bool,
    /// Also fit both slabs' absorption (one factor) to the cube's time
    /// profile, and use it.
    #[cfg_attr(feature = "cli", arg(long = "fit-absorption"))]
    pub fit_absorption: bool,
    /// The background the lab subtracted from the counts: counts per pixel
    /// and bin, or a file of them per pixel (rows, cols) or a background
    /// recording (its mean over time per pixel). Needed only where the
    /// cube has too few bins before the light to measure it.
    #[cfg_attr(
        feature = "cli",
        arg(long = "subtracted-background", value_name = "COUNTS|FILE")
    )]
    pub subtracted_background: Option<String>,
    /// Bad pixels: a (rows, cols) array whose non-zero entries are left
    /// out (filtered, hot and dead pixels are found without it).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub mask: Option<PathBuf>,
    /// The instrument's response: a 1-D array (.npy, .mat) or a CSV of one
    /// number per line (its last column), taken as given.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "FILE", requires = "irf_bin_width_ps")
    )]
    pub irf: Option<PathBuf>,
    /// Bin width of --irf, with its unit.
    #[cfg_attr(feature = "cli", arg(long = "irf-bin-width", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub irf_bin_width_ps: Option<f64>,
    /// Time groups of equal light the bins after the light's onset are
    /// summed into (1: the time-summed cube).
    #[cfg_attr(feature = "cli", arg(long = "time-groups", default_value_t = super::DEFAULT_TIME_GROUPS))]
    pub time_groups: usize,
    /// The most iterations the stop searches.
    #[cfg_attr(feature = "cli", arg(long = "max-iters", default_value_t = super::DEFAULT_MAX_ITERS))]
    pub max_iters: usize,
    /// Run this many iterations instead of choosing them (no search).
    #[cfg_attr(feature = "cli", arg(long))]
    pub iterations: Option<usize>,
}

/// A reconstruction done and written.
#[derive(Debug)]
pub struct EmbeddedDone {
    /// What was found and done.
    pub outcome: Outcome,
    /// The files written.
    pub files: Vec<PathBuf>,
}

impl EmbeddedRequest {
    /// The cube read and its settings, every file read and checked.
    pub fn load(&self) -> Result<(super::cube::Cube, Settings), String> {
        let axes = match &self.axes {
            Some(a) => Axes::parse(a)?,
            None if Format::of_file(&self.cube) == Format::Npy => Axes::parse("tyx")?,
            None => Axes::MATLAB,
        };
        let positions = match (&self.positions, &self.pitch) {
            (Some(path), _) => Positions::File {
                path: path.clone(),
                unit_cm: self.positions_unit_cm.ok_or_else(|| {
                    format!(
                        "{}: the positions' unit is needed (--positions-unit 1mm, 1cm or 1m)",
                        path.display()
                    )
                })?,
                names: self
                    .positions_names
                    .as_deref()
                    .map(|n| {
                        n.split_once(',')
                            .map(|(a, b)| (a.trim().to_string(), b.trim().to_string()))
                            .ok_or_else(|| format!("--positions-names `{n}`: two names X,Y"))
                    })
                    .transpose()?,
            },
            (None, Some(p)) => {
                let (x, y) = match p.split_once(',') {
                    Some(_) => pair_cm(p)?,
                    None => {
                        let v = crate::units::parse_positive_cm(p)?;
                        (v, v)
                    }
                };
                Positions::Pitch(x, y)
            }
            (None, None) => {
                return Err(format!(
                    "{}: where the pixels sit is needed: --positions FILE (with --positions-unit) or --pitch LENGTH",
                    self.cube.display()
                ));
            }
        };
        let cube = super::cube::read(&self.cube, self.variable.as_deref(), axes, &positions)?;
        let shape = (cube.values.dim().1, cube.values.dim().2);
        let mask = match &self.mask {
            Some(path) => {
                let a = lab_array::pick(path, None, "mask (a 2-D array)", |s| s.len() == 2)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                let used = super::pixels::mask_from(&a.values, shape)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                if !used.iter().any(|&u| u) {
                    return Err(format!(
                        "{}: the mask leaves out every pixel",
                        path.display()
                    ));
                }
                Some(used)
            }
            None => None,
        };
        let subtracted = self
            .subtracted_background
            .as_deref()
            .map(|s| subtracted(s, shape))
            .transpose()?;
        let irf = match (&self.irf, self.irf_bin_width_ps) {
            (Some(path), Some(width)) => Some(read_irf(path, width)?),
            _ => None,
        };
        let settings = Settings {
            geometry: self.geometry.geometry(irf)?,
            bin_width_ps: self.bin_width_ps,
            time_zero_ps: self.time_zero_ps,
            fit_media: super::calibrate::Free {
                scattering: self.fit_scattering,
                absorption: self.fit_absorption,
            },
            time_groups: self.time_groups,
            max_iters: self.max_iters,
            iterations: self.iterations,
            subtracted,
            mask,
        };
        Ok((cube, settings))
    }

    /// Reads, reconstructs and writes into `out`.
    pub fn run(&self, out: &Path) -> Result<EmbeddedDone, String> {
        let (cube, settings) = self.load()?;
        let outcome = super::reconstruct(&cube, &settings).map_err(|e| e.to_string())?;
        let mut inputs: Vec<&Path> = vec![&self.cube];
        inputs.extend(self.positions.as_deref());
        inputs.extend(self.mask.as_deref());
        inputs.extend(self.irf.as_deref());
        let files = super::write(&outcome, out, &inputs)?;
        Ok(EmbeddedDone { outcome, files })
    }
}

/// `--subtracted-background`: a number, or a file of a per-pixel map or a
/// background recording.
fn subtracted(text: &str, shape: (usize, usize)) -> Result<Subtracted, String> {
    if let Ok(v) = text.parse::<f64>() {
        return if v.is_finite() && v >= 0.0 {
            Ok(Subtracted::Level(v))
        } else {
            Err(format!(
                "--subtracted-background {text}: counts per pixel and bin, at least 0"
            ))
        };
    }
    let path = Path::new(text);
    let a = lab_array::pick(path, None, "background (2-D map or 3-D recording)", |s| {
        s.len() == 2 || s.len() == 3
    })
    .map_err(|e| format!("{}: {e}", path.display()))?;
    let v = &a.values;
    let map: Array2<f64> = match v.ndim() {
        2 => v.view().into_dimensionality().expect("2-D").to_owned(),
        3 => {
            // A recording of the same camera: rows and columns are the
            // axes of the cube's shape, time the other one.
            let s = v.shape();
            let t = (0..3)
                .find(|&t| {
                    let rest: Vec<usize> = (0..3).filter(|&a| a != t).map(|a| s[a]).collect();
                    rest == [shape.0, shape.1]
                })
                .ok_or_else(|| {
                    format!(
                        "{}: a recording of shape {s:?} for a cube of {} x {} pixels",
                        path.display(),
                        shape.0,
                        shape.1
                    )
                })?;
            v.mean_axis(ndarray::Axis(t))
                .expect("bins")
                .into_dimensionality()
                .expect("2-D")
        }
        _ => unreachable!("picked for 2 or 3 dimensions"),
    };
    if map.dim() != shape {
        return Err(format!(
            "{}: a background of {:?} for a cube of {} x {} pixels",
            path.display(),
            map.dim(),
            shape.0,
            shape.1
        ));
    }
    if let Some(v) = map.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(format!(
            "{}: a background value of {v}: counts are finite and at least 0",
            path.display()
        ));
    }
    Ok(Subtracted::Map(map))
}

/// An instrument response from a 1-D array file or a CSV, on bins of
/// `width_ps` from 0, taken as given (no time zero moved, nothing
/// subtracted).
pub fn read_irf(path: &Path, width_ps: f64) -> Result<IrfTable, String> {
    let named = |e: String| format!("{}: {e}", path.display());
    let values: Vec<f64> = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv") || e.eq_ignore_ascii_case("txt"))
    {
        let text = crate::files::read_bounded(path, 64 << 20, "instrument response")
            .map_err(|e| e.to_string())?;
        let text = String::from_utf8_lossy(&text);
        let mut out = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let last = line
                .split([',', ';', '\t'])
                .next_back()
                .unwrap_or("")
                .trim();
            if last.is_empty() {
                continue;
            }
            match last.parse::<f64>() {
                Ok(v) => out.push(v),
                Err(_) if out.is_empty() && i == 0 => {} // a header
                Err(_) => return Err(named(format!("line {}: `{last}` is not a number", i + 1))),
            }
        }
        out
    } else {
        let a = lab_array::pick(path, None, "response (a 1-D array)", |s| {
            s.iter().filter(|&&d| d > 1).count() <= 1
        })
        .map_err(named)?;
        a.values.iter().copied().collect()
    };
    IrfTable::new(width_ps, 0.0, values).map_err(|e| named(e.to_string()))
}

/// A simulated cube of the object inside the medium, written as a lab
/// publishes one.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SimulateEmbeddedRequest {
    /// The target: letter:A (a capital letter) or slits:CM (two slits
    /// that far apart, centre to centre).
    #[cfg_attr(feature = "cli", arg(long))]
    pub target: String,
    /// Both slabs and the beam.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub geometry: GeometryArgs,
    /// Camera pixels, rows and columns.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 32))]
    pub pixels: usize,
    /// Pixel pitch on the imaged face, with its unit.
    #[cfg_attr(feature = "cli", arg(long, value_name = "LENGTH", default_value = "1.4mm", value_parser = crate::units::parse_positive_cm))]
    pub pitch: f64,
    /// Time bins.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 256))]
    pub bins: usize,
    /// Bin width with its unit.
    #[cfg_attr(feature = "cli", arg(long = "bin-width", value_name = "TIME", default_value = "50ps", value_parser = crate::units::parse_ps))]
    pub bin_width_ps: f64,
    /// The pulse's entry into the front slab after bin 0's start.
    #[cfg_attr(feature = "cli", arg(long = "time-zero", value_name = "TIME", default_value = "1000ps", value_parser = crate::units::parse_ps))]
    pub time_zero_ps: f64,
    /// Net photons in the cube.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 4e5))]
    pub photons: f64,
    /// Dark counts per pixel and bin, drawn per pixel between these.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "LO,HI", default_value = "10,30")
    )]
    pub dark: String,
    /// What the lab's background subtraction leaves per pixel and bin.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "LO,HI", default_value = "2.6,8.7")
    )]
    pub residual: String,
    /// Variance per unit mean of the camera's counts (1: photon counting).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1.0))]
    pub gain: f64,
    /// Filtered, hot and dead pixels.
    #[cfg_attr(
        feature = "cli",
        arg(long = "bad-pixels", value_name = "F,H,D", default_value = "20,2,2")
    )]
    pub bad_pixels: String,
    /// Seed of every draw.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1))]
    pub seed: u64,
}

impl SimulateEmbeddedRequest {
    /// Simulates and writes OUT/cube.mat, OUT/positions.mat (mm) and
    /// OUT/truth.npy.
    pub fn run(&self, out: &Path) -> Result<Vec<PathBuf>, String> {
        let numbers = |name: &str, text: &str, n: usize| -> Result<Vec<f64>, String> {
            let v: Vec<f64> = text
                .split(',')
                .map(|t| t.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| format!("--{name} `{text}`: {n} numbers separated by commas"))?;
            if v.len() != n || v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                return Err(format!("--{name} `{text}`: {n} numbers of at least 0"));
            }
            Ok(v)
        };
        let dark = numbers("dark", &self.dark, 2)?;
        let residual = numbers("residual", &self.residual, 2)?;
        let bad = numbers("bad-pixels", &self.bad_pixels, 3)?;
        if dark[0] > dark[1] || residual[0] > residual[1] || residual[1] > dark[0] {
            return Err(
                "--dark and --residual: LO <= HI, and what is left at most the dark counts".into(),
            );
        }
        if !(self.gain.is_finite()
            && self.gain > 0.0
            && self.photons.is_finite()
            && self.photons > 0.0)
        {
            return Err("--gain and --photons must be positive".into());
        }
        let target = Target::parse(&self.target)?;
        let geometry = self.geometry.geometry(None)?;
        let truth = target.render((self.pixels, self.pixels), self.pitch);
        let rec = Recording {
            photons: self.photons,
            dark: (dark[0], dark[1]),
            residual: (residual[0], residual[1]),
            gain: self.gain,
            filtered: bad[0] as usize,
            hot: bad[1] as usize,
            dead: bad[2] as usize,
            seed: self.seed,
        };
        let sim = super::simulate::simulate(
            &geometry,
            &truth,
            self.pitch,
            (self.bins, self.bin_width_ps),
            self.time_zero_ps,
            &rec,
        )?;
        std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
        super::simulate::write_as_lab(&sim.cube, (self.pitch, self.pitch), out)
            .map_err(|e| format!("{}: {e}", out.display()))?;
        let truth_path = out.join("truth.npy");
        crate::formats::image::write_image(sim.truth.view(), &truth_path)
            .map_err(|e| e.to_string())?;
        Ok(vec![
            out.join("cube.mat"),
            out.join("positions.mat"),
            truth_path,
        ])
    }
}
