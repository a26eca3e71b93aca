//! Monte Carlo photon transport through a slab or a semi-infinite
//! medium: the reference the diffusion approximation is judged against
//! where it fails (thin or weakly scattering media, early photons).
//!
//! The scheme is MCML's (Wang, Jacques and Zheng, Comput. Methods
//! Programs Biomed. 47, 131 (1995)) with absorption by path length (as
//! MCX weighs its photons): a photon packet enters the front face at the
//! origin along the normal (a pencil beam), less the specular reflection
//! of the index step; it flies exponential free paths of the scattering
//! coefficient, scatters by the Henyey-Greenstein phase function, and at
//! a face is reflected with the unpolarised Fresnel probability (all or
//! nothing, so that each packet leaves once, at one place and time) or
//! leaves. Its weight on leaving is `exp(-mu_a L)` of its path `L`; the
//! rest was absorbed. Below a weight of [`ROULETTE_WEIGHT`] a packet
//! survives a roulette of one in [`ROULETTE_CHANCE`] with its weight
//! multiplied to match, so no weight is lost on average. With no
//! absorption a packet that has not left after [`Run::max_path_cm`] is
//! stopped and its weight counted as cut.
//!
//! Every packet's exit through the far face is recorded by time of
//! flight (`n L / c`) and distance from the beam's axis, with the squared
//! weights so that every tally carries its standard error. Packets run in
//! fixed chunks, each from its own seeded generator and summed in chunk
//! order: a run is the same on any number of cores.

use ndarray::Array2;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use thiserror::Error;

use crate::diffusion::light_speed_cm_per_ps;
use crate::slab::fresnel_unpolarised_sin_cos;

/// Weight below which a packet plays the roulette.
pub const ROULETTE_WEIGHT: f64 = 1e-4;

/// One in this many packets survives the roulette.
pub const ROULETTE_CHANCE: f64 = 10.0;

/// Packets per chunk: each chunk has its own generator.
const CHUNK: u64 = 1 << 14;

/// A homogeneous slab between two half-spaces of index `n_outside`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slab {
    /// Absorption coefficient (1/cm), >= 0.
    pub mu_a_per_cm: f64,
    /// Scattering coefficient (1/cm), >= 0.
    pub mu_s_per_cm: f64,
    /// Henyey-Greenstein anisotropy, in (-1, 1).
    pub g: f64,
    /// The slab's refractive index, >= 1.
    pub n: f64,
    /// The index outside both faces, >= 1.
    pub n_outside: f64,
    /// Thickness (cm), > 0; infinite for a semi-infinite medium (light
    /// leaves by the front face only).
    pub thickness_cm: f64,
}

/// Where and how light enters the slab, at the origin of its front face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// A pencil beam along the normal from outside: the index step's
    /// specular reflection stays outside.
    Pencil,
    /// A collimated beam along the normal from outside whose irradiance on
    /// the face is Gaussian about the origin, falling to `1/e^2` at
    /// `radius_cm` (a laser beam's waist at the face; for the object inside
    /// the medium, lit through the front slab); the specular reflection
    /// stays outside.
    GaussianBeam {
        /// The `1/e^2` radius of the irradiance (cm), > 0.
        radius_cm: f64,
    },
    /// A point of an object in contact with the face, emitting into the
    /// slab by Lambert's cosine law (a diffuse reflector or fluorophore
    /// behind the slab: the object plane of the paper's geometry).
    Lambertian,
    /// A point emitting into the slab evenly over the forward hemisphere.
    Hemisphere,
}

impl Source {
    /// The light that enters, of one packet.
    fn entered(self, slab: &Slab) -> f64 {
        match self {
            Source::Pencil | Source::GaussianBeam { .. } => 1.0 - slab.specular(),
            Source::Lambertian | Source::Hemisphere => 1.0,
        }
    }

    /// Where a packet enters: the origin, or for a Gaussian beam a point
    /// drawn from its irradiance (`r = w sqrt(-ln(1 - u) / 2)`).
    fn start<R: Rng>(self, rng: &mut R) -> [f64; 3] {
        match self {
            Source::GaussianBeam { radius_cm } => {
                let r = radius_cm * (-(1.0 - rng.random::<f64>()).ln() / 2.0).sqrt();
                let (s, c) = (2.0 * std::f64::consts::PI * rng.random::<f64>()).sin_cos();
                [r * c, r * s, 0.0]
            }
            _ => [0.0; 3],
        }
    }

    /// A first direction.
    fn direction<R: Rng>(self, rng: &mut R) -> [f64; 3] {
        let cos_t = match self {
            Source::Pencil | Source::GaussianBeam { .. } => return [0.0, 0.0, 1.0],
            // Lambert: cos^2 uniform; the hemisphere: cos uniform.
            Source::Lambertian => (1.0 - rng.random::<f64>()).sqrt(),
            Source::Hemisphere => 1.0 - rng.random::<f64>(),
        };
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * rng.random::<f64>()).sin_cos();
        [sin_t * c, sin_t * s, cos_t]
    }
}

/// Where transmitted light is recorded: time bins and radial rings on the
/// far face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Start of the first time bin (ps after the packet enters).
    pub t_start_ps: f64,
    /// Width of each time bin (ps), > 0.
    pub bin_width_ps: f64,
    /// Time bins.
    pub bins: usize,
    /// Width of each ring (cm), > 0.
    pub ring_width_cm: f64,
    /// Rings, from the beam's axis out.
    pub rings: usize,
}

/// How many packets, from which seed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    /// Packets launched.
    pub photons: u64,
    /// The seed: the same seed gives the same result on any machine.
    pub seed: u64,
    /// A packet still inside after this path (cm) is stopped and its
    /// weight counted as cut: needed without absorption, where nothing
    /// else ends a packet that keeps reflecting inside.
    pub max_path_cm: f64,
}

impl From<TransportError> for crate::error::ParamError {
    fn from(e: TransportError) -> Self {
        match e {
            TransportError::Parameter { field, value, why } => {
                Self::new(field, value, format!("Monte Carlo transport: {why}"))
            }
        }
    }
}

/// Bad input to a transport run.
#[derive(Debug, Error, PartialEq)]
pub enum TransportError {
    /// A parameter outside its range, named with its value.
    #[error("{field} = {value}: {why}")]
    Parameter {
        /// The parameter.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
}

fn check(
    field: &'static str,
    value: f64,
    ok: bool,
    why: &'static str,
) -> Result<(), TransportError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(TransportError::Parameter { field, value, why })
    }
}

impl Slab {
    /// van de Hulst's slab, MCML's check case (Wang, Jacques and Zheng
    /// 1995): mu_a 10 /cm, mu_s 90 /cm, g 0.75, n 1 inside and out,
    /// 0.02 cm; a pencil beam's diffuse reflectance is 0.09739 and its
    /// total transmittance 0.66096.
    pub const VAN_DE_HULST: Slab = Slab {
        mu_a_per_cm: 10.0,
        mu_s_per_cm: 90.0,
        g: 0.75,
        n: 1.0,
        n_outside: 1.0,
        thickness_cm: 0.02,
    };

    /// The slab of a setup's medium, in air on both sides.
    pub fn in_air(m: &crate::params::Medium) -> Self {
        Self {
            mu_a_per_cm: m.mu_a_per_cm,
            mu_s_per_cm: m.mu_s_per_cm,
            g: m.g,
            n: m.refractive_index,
            n_outside: 1.0,
            thickness_cm: m.thickness_cm,
        }
    }

    /// Checks every parameter, naming the first out of range.
    pub fn validate(&self) -> Result<(), TransportError> {
        check(
            "mu_a",
            self.mu_a_per_cm,
            self.mu_a_per_cm >= 0.0,
            "give an absorption coefficient >= 0 (1/cm)",
        )?;
        check(
            "mu_s",
            self.mu_s_per_cm,
            self.mu_s_per_cm >= 0.0,
            "give a scattering coefficient >= 0 (1/cm)",
        )?;
        check(
            "g",
            self.g,
            self.g > -1.0 && self.g < 1.0,
            "the anisotropy lies in (-1, 1): at 1 light does not scatter, give mu_s 0 instead",
        )?;
        check("n", self.n, self.n >= 1.0, "give a refractive index >= 1")?;
        check(
            "n_outside",
            self.n_outside,
            self.n_outside >= 1.0,
            "give a refractive index >= 1",
        )?;
        if self.thickness_cm == f64::INFINITY {
            // A semi-infinite medium: light leaves by the front face only.
            return Ok(());
        }
        check(
            "thickness",
            self.thickness_cm,
            self.thickness_cm > 0.0,
            "give a thickness > 0 (cm), or infinity for a semi-infinite medium",
        )
    }

    /// The specular reflection of the front face at normal incidence.
    pub fn specular(&self) -> f64 {
        ((self.n_outside - self.n) / (self.n_outside + self.n)).powi(2)
    }
}

/// A mean per launched packet and its standard error.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    /// The mean.
    pub mean: f64,
    /// Its standard error.
    pub error: f64,
}

/// Sums of weights and squared weights.
#[derive(Debug, Clone, Default, PartialEq)]
struct Sums {
    w: f64,
    w2: f64,
}

impl Sums {
    fn add(&mut self, w: f64) {
        self.w += w;
        self.w2 += w * w;
    }

    fn merge(&mut self, o: &Sums) {
        self.w += o.w;
        self.w2 += o.w2;
    }

    fn estimate(&self, n: f64) -> Estimate {
        let mean = self.w / n;
        let var = (self.w2 / n - mean * mean).max(0.0) / (n - 1.0).max(1.0);
        Estimate {
            mean,
            error: var.sqrt(),
        }
    }
}

/// The tallies of a chunk or a run.
#[derive(Debug, Clone, Default)]
struct Tally {
    reflected: Sums,
    transmitted: Sums,
    absorbed: Sums,
    cut: Sums,
    late: Sums,
    /// Rings x bins, ring-major.
    cells: Vec<Sums>,
    /// Per time bin, the whole face.
    face: Vec<Sums>,
}

impl Tally {
    fn new(grid: &Grid) -> Self {
        Self {
            cells: vec![Sums::default(); grid.rings * grid.bins],
            face: vec![Sums::default(); grid.bins],
            ..Self::default()
        }
    }

    fn merge(&mut self, o: &Tally) {
        self.reflected.merge(&o.reflected);
        self.transmitted.merge(&o.transmitted);
        self.absorbed.merge(&o.absorbed);
        self.cut.merge(&o.cut);
        self.late.merge(&o.late);
        self.cells
            .iter_mut()
            .zip(&o.cells)
            .for_each(|(a, b)| a.merge(b));
        self.face
            .iter_mut()
            .zip(&o.face)
            .for_each(|(a, b)| a.merge(b));
    }
}

/// What a run found, per launched packet.
#[derive(Debug, Clone)]
pub struct Transport {
    /// Packets launched.
    pub photons: u64,
    /// The front face's specular reflection of the entering light (exact;
    /// 0 for a source inside the face).
    pub specular: f64,
    /// Light leaving the front face after entering (diffuse reflectance).
    pub reflected: Estimate,
    /// Light leaving the far face (total transmittance, ballistic light
    /// included).
    pub transmitted: Estimate,
    /// Light absorbed.
    pub absorbed: Estimate,
    /// Light of packets stopped by the path cap.
    pub cut: Estimate,
    /// Transmitted light before or after the grid's time bins (light in
    /// them but past the last ring is in `face`, not in `cells`).
    pub outside_grid: Estimate,
    /// The grid transmitted light is recorded on.
    pub grid: Grid,
    /// Transmitted light per ring and time bin (ring-major), per packet,
    /// not yet divided by area or bin width.
    pub cells: Vec<Estimate>,
    /// Transmitted light per time bin over the whole face.
    pub face: Vec<Estimate>,
}

impl Transport {
    /// Time bin `k`'s transmitted light on a grid of `h` x `w` square
    /// pixels of side `pitch_cm`, the beam's axis at the centre of pixel
    /// `(h / 2, w / 2)`, per packet and pixel ([`rings_to_pixels`]), with
    /// each value's standard error (its rings' errors added as if
    /// correlated: an upper bound). Light past the last ring is left out.
    pub fn pixel_kernel(
        &self,
        k: usize,
        pitch_cm: f64,
        shape: (usize, usize),
    ) -> (Array2<f64>, Array2<f64>) {
        let g = &self.grid;
        let ring = |f: fn(&Estimate) -> f64| -> Vec<f64> {
            (0..g.rings)
                .map(|j| f(&self.cells[j * g.bins + k]))
                .collect()
        };
        (
            rings_to_pixels(&ring(|e| e.mean), g.ring_width_cm, pitch_cm, shape),
            rings_to_pixels(&ring(|e| e.error), g.ring_width_cm, pitch_cm, shape),
        )
    }

    /// The transmittance's time density over the whole face at bin `k`
    /// (per ps) and its standard error.
    pub fn face_density(&self, k: usize) -> Estimate {
        let e = self.face[k];
        Estimate {
            mean: e.mean / self.grid.bin_width_ps,
            error: e.error / self.grid.bin_width_ps,
        }
    }
}

/// Light per ring (rings of `ring_width_cm` about the axis) spread
/// evenly over each ring's area onto `h` x `w` square pixels of side
/// `pitch_cm`, the axis at the centre of pixel `(h / 2, w / 2)`: each
/// pixel sampled at 8 x 8 points. Light past the last ring is left out.
pub fn rings_to_pixels(
    per_ring: &[f64],
    ring_width_cm: f64,
    pitch_cm: f64,
    (h, w): (usize, usize),
) -> Array2<f64> {
    const SUB: usize = 8;
    let per_area: Vec<f64> = per_ring
        .iter()
        .enumerate()
        .map(|(j, v)| {
            v / (std::f64::consts::PI * ring_width_cm * ring_width_cm * (2 * j + 1) as f64)
        })
        .collect();
    let cell = pitch_cm * pitch_cm / (SUB * SUB) as f64;
    let offset = |i: usize, centre: usize, sub: usize| {
        (i as f64 - centre as f64 - 0.5 + (sub as f64 + 0.5) / SUB as f64) * pitch_cm
    };
    Array2::from_shape_fn((h, w), |(r, c)| {
        let mut v = 0.0;
        for i in 0..SUB {
            let y = offset(r, h / 2, i);
            for j in 0..SUB {
                let x = offset(c, w / 2, j);
                let ring = ((x * x + y * y).sqrt() / ring_width_cm) as usize;
                if let Some(d) = per_area.get(ring) {
                    v += d * cell;
                }
            }
        }
        v
    })
}

/// The Monte Carlo kernels of a setup's time bins.
#[derive(Debug, Clone)]
pub struct SetupKernels {
    /// Per bin of the setup: its kernel on the sensor (centred: the
    /// object point under pixel `(h / 2, w / 2)`), photons per emitted
    /// packet; `None` where no light was recorded.
    pub kernels: Vec<Option<Array2<f64>>>,
    /// Per bin: the relative standard error of its light.
    pub relative_errors: Vec<f64>,
    /// What the run cache did ([`crate::transport_cache`]).
    pub cache: crate::transport_cache::CacheUse,
}

/// The arrivals a setup's bins record: a fine time grid from the earliest
/// arrival an instrument response can carry into the first bin to the
/// latest it can carry into the last (tallied in eighths of a bin with a
/// response, or finer to a measured table's own bins, at most 32 to a
/// bin), and each bin's chance of recording each fine step.
struct Arrivals {
    start_ps: f64,
    /// The latest arrival the last bin can record.
    end_ps: f64,
    fine_ps: f64,
    steps: usize,
}

impl Arrivals {
    fn of(setup: &crate::params::Setup) -> Self {
        let irf = setup.irf.as_ref();
        let bins = &setup.bins;
        let sub = match irf {
            None => 1,
            Some(crate::irf::InstrumentResponse::Parametric(_)) => 8,
            Some(crate::irf::InstrumentResponse::Measured(t)) => {
                ((bins.width_ps / t.bin_ps()).ceil() as usize).clamp(8, 32)
            }
        };
        let fine_ps = bins.width_ps / sub as f64;
        let (lo, hi) = irf.map_or((0.0, 0.0), |i| i.support_ps());
        let start_ps = if irf.is_some() {
            bins.start_ps - hi - fine_ps
        } else {
            bins.start_ps
        };
        let end_ps = bins.end_ps() - lo;
        let steps = ((end_ps - start_ps) / fine_ps).ceil().max(1.0) as usize;
        Self {
            start_ps,
            end_ps,
            fine_ps,
            steps,
        }
    }

    /// The transport grid of these arrivals with `rings` rings of
    /// `ring_width_cm`, and the run of `packets` from `seed` (light later
    /// than the grid's end reaches no bin: the path cap).
    fn grid_and_run(
        &self,
        setup: &crate::params::Setup,
        (ring_width_cm, rings): (f64, usize),
        packets: u64,
        seed: u64,
    ) -> (Grid, Run) {
        let grid = Grid {
            t_start_ps: self.start_ps,
            bin_width_ps: self.fine_ps,
            bins: self.steps,
            ring_width_cm,
            rings,
        };
        let run = Run {
            photons: packets,
            seed,
            max_path_cm: (self.end_ps + self.fine_ps)
                * light_speed_cm_per_ps(setup.medium.refractive_index),
        };
        (grid, run)
    }

    /// Each fine step's chance of being recorded in bin `k` of `setup`.
    fn chance(&self, setup: &crate::params::Setup, k: usize) -> Vec<f64> {
        let (ta, tb) = setup.bins.edges_ps(k);
        (0..self.steps)
            .map(|f| {
                let centre = self.start_ps + (f as f64 + 0.5) * self.fine_ps;
                match &setup.irf {
                    Some(i) => i.bin_weight(ta, tb, centre),
                    None => f64::from(u8::from(centre >= ta && centre < tb)),
                }
            })
            .collect()
    }
}

/// Kernels of `setup`'s bins by Monte Carlo transport: `packets` packets
/// from a point of the object at the slab's back face, emitting into it
/// by Lambert's law (air outside both faces); an instrument response,
/// parametric or a measured table, spreads each arrival over the bins
/// (arrivals tallied in eighths of a bin, or finer to the table's own bins,
/// at most 32 to a bin).
pub fn setup_kernels(
    setup: &crate::params::Setup,
    packets: u64,
    seed: u64,
) -> Result<SetupKernels, crate::error::ParamError> {
    let slab = Slab::in_air(&setup.medium);
    slab.validate()?;
    let arrivals = Arrivals::of(setup);
    let pitch = setup.sensor.pixel_pitch_cm();
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    let half_diagonal = 0.5 * pitch * ((h * h + w * w) as f64).sqrt() + pitch;
    let ring_width = pitch / 2.0;
    let rings = (half_diagonal / ring_width).ceil() as usize;
    let (grid, run) = arrivals.grid_and_run(setup, (ring_width, rings), packets, seed);
    let (t, cache) =
        crate::transport_cache::transport_cached(&slab, Source::Lambertian, &grid, &run)?;
    let steps = arrivals.steps;
    let mut kernels = Vec::with_capacity(setup.bins.count);
    let mut relative_errors = Vec::with_capacity(setup.bins.count);
    for k in 0..setup.bins.count {
        let chance = arrivals.chance(setup, k);
        let (mut rings, mut var) = (vec![0.0; grid.rings], 0.0);
        for (j, r) in rings.iter_mut().enumerate() {
            for (f, &p) in chance.iter().enumerate() {
                if p > 0.0 {
                    let e = t.cells[j * steps + f];
                    *r += p * e.mean;
                    var += (p * e.error).powi(2);
                }
            }
        }
        let light: f64 = rings.iter().sum();
        relative_errors.push(if light > 0.0 {
            var.sqrt() / light
        } else {
            f64::INFINITY
        });
        kernels.push((light > 0.0).then(|| rings_to_pixels(&rings, ring_width, pitch, (h, w))));
    }
    Ok(SetupKernels {
        kernels,
        relative_errors,
        cache,
    })
}

/// Light in each bin of `setup` per packet by Monte Carlo transport of
/// `packets` packets from `seed`, launched as [`setup_kernels`] launches
/// them and recorded through the setup's instrument response: within
/// `radius_cm` of the axis, or over the whole far face (`None`). Not
/// cached: its callers ask for many media, or few packets, once each.
pub fn setup_light(
    setup: &crate::params::Setup,
    radius_cm: Option<f64>,
    packets: u64,
    seed: u64,
) -> Result<Vec<f64>, crate::error::ParamError> {
    let slab = Slab::in_air(&setup.medium);
    slab.validate()?;
    let arrivals = Arrivals::of(setup);
    let ring = radius_cm.unwrap_or(1.0);
    let (grid, run) = arrivals.grid_and_run(setup, (ring, 1), packets, seed);
    let t = transport(&slab, Source::Lambertian, &grid, &run)?;
    // One ring: its cells are the light within it, per fine step.
    let recorded = match radius_cm {
        Some(_) => &t.cells,
        None => &t.face,
    };
    Ok((0..setup.bins.count)
        .map(|k| {
            let chance = arrivals.chance(setup, k);
            chance.iter().zip(recorded).map(|(p, e)| p * e.mean).sum()
        })
        .collect())
}

/// Share of the light in each bin of `setup` over the whole far face (no
/// pixels, no sensor edges) by [`setup_light`]: the time profile
/// `calibrate` fits under the Monte Carlo medium (the same seed for every
/// medium, so nearby media share their packets' random numbers).
pub fn setup_profile(
    setup: &crate::params::Setup,
    packets: u64,
    seed: u64,
) -> Result<Vec<f64>, crate::error::ParamError> {
    let light = setup_light(setup, None, packets, seed)?;
    let total: f64 = light.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return Err(crate::error::ParamError::new(
            "bins",
            setup.bins.end_ps(),
            format!(
                "Monte Carlo transport records no light in these bins: the first light crosses the slab at n d / c = {:.1} ps",
                setup.medium.first_light_ps()
            ),
        ));
    }
    Ok(light.iter().map(|l| l / total).collect())
}

/// Packets of the time profile a fit evaluates per medium
/// ([`setup_profile`]): a twentieth of the kernels'.
pub const PROFILE_PACKETS: u64 = 200_000;

/// Packets a setup's kernels are made of by default.
pub const SETUP_PACKETS: u64 = 4_000_000;

/// The seed of a setup's kernels: the same setup gives the same kernels.
pub const SETUP_SEED: u64 = 0x5ca7_7e25;

/// Runs `run` packets from `source` through `slab`, recording
/// transmitted light on `grid`.
pub fn transport(
    slab: &Slab,
    source: Source,
    grid: &Grid,
    run: &Run,
) -> Result<Transport, TransportError> {
    slab.validate()?;
    check(
        "bin width",
        grid.bin_width_ps,
        grid.bin_width_ps > 0.0,
        "give a bin width > 0 (ps)",
    )?;
    check(
        "ring width",
        grid.ring_width_cm,
        grid.ring_width_cm > 0.0,
        "give a ring width > 0 (cm)",
    )?;
    check(
        "time start",
        grid.t_start_ps,
        true,
        "give a finite start (ps)",
    )?;
    check(
        "photons",
        run.photons as f64,
        run.photons >= 2,
        "give at least 2 packets",
    )?;
    check(
        "max path",
        run.max_path_cm,
        run.max_path_cm > 0.0,
        "give a path cap > 0 (cm)",
    )?;
    if let Source::GaussianBeam { radius_cm } = source {
        check(
            "beam radius",
            radius_cm,
            radius_cm > 0.0,
            "give the beam's 1/e^2 radius > 0 (cm); a pencil beam for none",
        )?;
    }
    let chunks = run.photons.div_ceil(CHUNK);
    let parts: Vec<Tally> = (0..chunks)
        .into_par_iter()
        .map(|i| {
            let n = CHUNK.min(run.photons - i * CHUNK);
            let mut rng = ChaCha8Rng::seed_from_u64(run.seed);
            rng.set_stream(i);
            let mut t = Tally::new(grid);
            for _ in 0..n {
                packet(slab, source, grid, run, &mut rng, &mut t);
            }
            t
        })
        .collect();
    let mut total = Tally::new(grid);
    for p in &parts {
        total.merge(p);
    }
    let n = run.photons as f64;
    Ok(Transport {
        photons: run.photons,
        specular: 1.0 - source.entered(slab),
        reflected: total.reflected.estimate(n),
        transmitted: total.transmitted.estimate(n),
        absorbed: total.absorbed.estimate(n),
        cut: total.cut.estimate(n),
        outside_grid: total.late.estimate(n),
        grid: *grid,
        cells: total.cells.iter().map(|s| s.estimate(n)).collect(),
        face: total.face.iter().map(|s| s.estimate(n)).collect(),
    })
}

/// A new direction after a Henyey-Greenstein scattering of `(ux, uy,
/// uz)` (MCML's update).
fn scatter<R: Rng>(g: f64, u: [f64; 3], rng: &mut R) -> [f64; 3] {
    let xi: f64 = rng.random();
    let cos_t = if g == 0.0 {
        2.0 * xi - 1.0
    } else {
        let f = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
        ((1.0 + g * g - f * f) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let psi = 2.0 * std::f64::consts::PI * rng.random::<f64>();
    let (sin_p, cos_p) = psi.sin_cos();
    let [ux, uy, uz] = u;
    if uz.abs() > 1.0 - 1e-12 {
        [sin_t * cos_p, sin_t * sin_p, cos_t * uz.signum()]
    } else {
        let tmp = (1.0 - uz * uz).sqrt();
        [
            sin_t * (ux * uz * cos_p - uy * sin_p) / tmp + ux * cos_t,
            sin_t * (uy * uz * cos_p + ux * sin_p) / tmp + uy * cos_t,
            -sin_t * cos_p * tmp + uz * cos_t,
        ]
    }
}

/// One packet, from entry to exit, absorption, the roulette or the cap.
fn packet<R: Rng>(slab: &Slab, source: Source, grid: &Grid, run: &Run, rng: &mut R, t: &mut Tally) {
    let (mu_a, mu_s, d) = (slab.mu_a_per_cm, slab.mu_s_per_cm, slab.thickness_cm);
    let mut pos = source.start(rng);
    let mut u = source.direction(rng);
    // The weight is `start * exp(-mu_a (path - from))`: `start` the
    // weight when the roulette last changed it (the entered light at
    // first), `from` the path then. What it lost since is absorbed.
    let (mut start, mut from, mut path) = (source.entered(slab), 0.0f64, 0.0f64);
    let weight = |path: f64, start: f64, from: f64| start * (-mu_a * (path - from)).exp();
    loop {
        let mut step = if mu_s > 0.0 {
            -(1.0 - rng.random::<f64>()).ln() / mu_s
        } else {
            f64::INFINITY
        };
        // Fly the step, meeting faces on the way.
        let left = loop {
            let to_face = if u[2] > 0.0 {
                (d - pos[2]) / u[2]
            } else if u[2] < 0.0 {
                -pos[2] / u[2]
            } else {
                f64::INFINITY
            };
            if step < to_face {
                for i in 0..3 {
                    pos[i] += step * u[i];
                }
                path += step;
                break false;
            }
            for i in 0..3 {
                pos[i] += to_face * u[i];
            }
            path += to_face;
            step -= to_face;
            if path > run.max_path_cm {
                break false;
            }
            let cos_i = u[2].abs();
            let reflected = fresnel_unpolarised_sin_cos(
                slab.n / slab.n_outside,
                (1.0 - cos_i * cos_i).max(0.0).sqrt(),
                cos_i,
            );
            if rng.random::<f64>() < reflected {
                u[2] = -u[2];
                continue;
            }
            break true;
        };
        let w = weight(path, start, from);
        if left {
            t.absorbed.add(start - w);
            if u[2] > 0.0 {
                t.transmitted.add(w);
                record(grid, slab, pos, path, w, t);
            } else {
                t.reflected.add(w);
            }
            return;
        }
        if path > run.max_path_cm {
            t.absorbed.add(start - w);
            t.cut.add(w);
            return;
        }
        if w < ROULETTE_WEIGHT {
            t.absorbed.add(start - w);
            if rng.random::<f64>() * ROULETTE_CHANCE >= 1.0 {
                // Ended: the survivors carry its weight on average.
                return;
            }
            (start, from) = (w * ROULETTE_CHANCE, path);
        }
        u = scatter(slab.g, u, rng);
    }
}

/// Records a packet of weight `w` leaving the far face at `pos` after
/// `path`.
fn record(grid: &Grid, slab: &Slab, pos: [f64; 3], path: f64, w: f64, t: &mut Tally) {
    let time = path / light_speed_cm_per_ps(slab.n);
    let k = ((time - grid.t_start_ps) / grid.bin_width_ps).floor();
    let r = (pos[0] * pos[0] + pos[1] * pos[1]).sqrt();
    let ring = (r / grid.ring_width_cm).floor();
    if k >= 0.0 && (k as usize) < grid.bins {
        let k = k as usize;
        t.face[k].add(w);
        if (ring as usize) < grid.rings {
            t.cells[ring as usize * grid.bins + k].add(w);
        }
    } else {
        t.late.add(w);
    }
}
