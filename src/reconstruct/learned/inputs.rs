//! What the learned reconstruction's network starts from: Richardson-Lucy
//! on the time-summed counts with the time-summed kernel (the model
//! `reconstruct` uses: the sensor's edges, the IRF in the kernels, the
//! background in the denominator), its iterates at [`CHECKPOINTS`], the
//! summed counts over the kernel mass, and two constant maps that say how
//! much light there is and how wide the blur is. Every image channel is
//! divided by one scale (the last iterate's mean), so the network works on
//! images of mean 1 whatever the stack's brightness. The trainer computes
//! its inputs with this same function (through the Python package).

use ndarray::{Array2, Array3, Axis};

use crate::forward::ForwardModel;
use crate::reconstruct::data::{Data, flat_level};
use crate::reconstruct::em::DENOMINATOR_GUARD;
use crate::reconstruct::rl_sum::RlOperator;

/// Richardson-Lucy iterations whose iterates are inputs; the last is the
/// base the network corrects.
pub const CHECKPOINTS: [usize; 3] = [10, 40, 150];

/// Input channels: the iterates, the scaled counts, the light level and
/// the blur width.
pub const CHANNELS: usize = CHECKPOINTS.len() + 3;

/// The channel of the last iterate, where the stages start.
pub const BASE_CHANNEL: usize = CHECKPOINTS.len() - 1;

/// A stack as the network sees it.
#[derive(Debug, Clone)]
pub struct LearnedInputs {
    /// `CHANNELS x H x W`, each image channel divided by `scale`.
    pub features: Array3<f32>,
    /// The last iterate's mean: the network's output times it is the
    /// object.
    pub scale: f64,
    /// Mean summed counts per sensor pixel.
    pub photons_per_pixel: f64,
    /// RMS radius of the time-summed kernel, pixels.
    pub kernel_width_px: f64,
    /// Background over mean counts (0 without a background).
    pub background_share: f64,
    /// The last iterate on the model's grid: where the stages start.
    pub base_grid: Vec<f64>,
    /// The time-summed counts on the sensor, row-major.
    pub counts: Vec<f64>,
    /// The background of the summed counts, per pixel.
    pub background: f64,
    /// The EM steps' denominator guard.
    pub guard: f64,
}

/// The light-level channel: `log10` of the mean counts per pixel, over
/// 3 (about -0.3 to 1 over the trained range).
pub fn level_feature(photons_per_pixel: f64) -> f32 {
    (photons_per_pixel.max(1e-3).log10() / 3.0) as f32
}

/// The blur channel: the kernel's RMS radius over 20 pixels.
pub fn width_feature(kernel_width_px: f64) -> f32 {
    (kernel_width_px / 20.0) as f32
}

/// The inputs of `data`; `None` without photons or kernel mass.
pub fn learned_inputs(data: &Data<'_>) -> Option<LearnedInputs> {
    let rl = RlOperator::new(data.model, data.bins);
    let summed = data.counts.sum_axis(Axis(0));
    let bg = data.model.background() * data.bins.len() as f64;
    let width = kernel_rms_radius(&data.model.summed(data.bins));
    summed_inputs(data.model, &rl, &summed, bg, width)
}

/// The inputs of counts summed over the bins of `rl` (`summed`, with
/// `background` per pixel, of a blur `kernel_width_px` wide): a stack's.
/// `None` without photons or kernel mass.
pub(crate) fn summed_inputs(
    model: &ForwardModel,
    rl: &RlOperator,
    summed: &Array2<f64>,
    bg: f64,
    kernel_width_px: f64,
) -> Option<LearnedInputs> {
    let (h, w) = summed.dim();
    let m: Vec<f64> = summed.iter().copied().collect();
    let total: f64 = m.iter().sum();
    if total <= 0.0 || rl.mass <= 0.0 {
        return None;
    }
    let guard = DENOMINATOR_GUARD * total / (h * w) as f64;
    let iterates = Iterated::flat(rl, &m, bg).continued(rl, &m, bg, guard);
    Some(assemble(
        model,
        rl,
        m,
        (bg, guard),
        iterates,
        kernel_width_px,
    ))
}

/// Richardson-Lucy from the flat object so far: its estimates at the
/// [`CHECKPOINTS`] reached and its estimate after `steps` steps.
pub(crate) struct Iterated {
    point: Vec<f64>,
    steps: usize,
    iterates: Vec<Vec<f64>>,
}

impl Iterated {
    /// A run at `point` after `steps` steps, `iterates` the estimates (on
    /// the grid) of the checkpoints it passed.
    pub(crate) fn from(point: Vec<f64>, steps: usize, iterates: Vec<Vec<f64>>) -> Self {
        Self {
            point,
            steps,
            iterates,
        }
    }

    /// A run not started: the flat object that predicts the photons of
    /// counts `m` (background `bg` per pixel) through `rl`.
    pub(crate) fn flat(rl: &RlOperator, m: &[f64], bg: f64) -> Self {
        let level = flat_level(m.iter().sum(), bg, 1, rl.mass, m.len());
        Self::from(vec![level; rl.len()], 0, Vec::new())
    }

    /// The run continued to the last checkpoint, for counts `m` with
    /// background `bg` and denominator guard `guard`: the checkpoints'
    /// estimates (on the grid).
    pub(crate) fn continued(
        mut self,
        rl: &RlOperator,
        m: &[f64],
        bg: f64,
        guard: f64,
    ) -> Vec<Vec<f64>> {
        let last = *CHECKPOINTS.last().expect("checkpoints");
        for it in self.steps + 1..=last {
            let y = rl.apply(&self.point);
            rl.update(&mut self.point, &y, m, bg, guard, false);
            if CHECKPOINTS.contains(&it) {
                self.iterates.push(self.point.clone());
            }
        }
        self.iterates
    }
}

/// The inputs from Richardson-Lucy's estimates at the [`CHECKPOINTS`]
/// (`iterates`, on the grid; the network starts from the last) of the
/// summed counts `m` with background and denominator guard `(bg, guard)`.
pub(crate) fn assemble(
    model: &ForwardModel,
    rl: &RlOperator,
    m: Vec<f64>,
    (bg, guard): (f64, f64),
    mut iterates: Vec<Vec<f64>>,
    kernel_width_px: f64,
) -> LearnedInputs {
    let (h, w) = model.sensor_shape();
    let total: f64 = m.iter().sum();
    let cropped: Vec<Vec<f64>> = iterates.iter().map(|g| model.crop_vec(g)).collect();
    let last = cropped.last().expect("the last checkpoint");
    let scale = (last.iter().sum::<f64>() / (h * w) as f64).max(f64::MIN_POSITIVE);
    let photons_per_pixel = total / (h * w) as f64;
    let mut features = Array3::<f32>::zeros((CHANNELS, h, w));
    for (c, it) in cropped.iter().enumerate() {
        fill(&mut features, c, it, 1.0 / scale);
    }
    fill(
        &mut features,
        CHECKPOINTS.len(),
        &m,
        1.0 / (rl.mass * scale),
    );
    features
        .index_axis_mut(Axis(0), CHECKPOINTS.len() + 1)
        .fill(level_feature(photons_per_pixel));
    features
        .index_axis_mut(Axis(0), CHECKPOINTS.len() + 2)
        .fill(width_feature(kernel_width_px));
    LearnedInputs {
        features,
        scale,
        photons_per_pixel,
        kernel_width_px,
        background_share: bg / photons_per_pixel,
        base_grid: iterates.pop().expect("the last checkpoint"),
        counts: m,
        background: bg,
        guard,
    }
}

/// Channel `c` of `features` from the row-major `values` times `factor`.
fn fill(features: &mut Array3<f32>, c: usize, values: &[f64], factor: f64) {
    features
        .index_axis_mut(Axis(0), c)
        .iter_mut()
        .zip(values)
        .for_each(|(f, &v)| *f = (v * factor) as f32);
}

/// RMS distance from its centre of the one kernel of `model` (a summed
/// model), in pixels: its second moment over its mass, the grid's
/// distances taken across the wrap (kernels are stored origin-centred).
pub fn kernel_rms_radius(model: &ForwardModel) -> f64 {
    let (gh, gw) = model.grid_shape();
    let kernel = model.fft().inverse(model.spectrum(0).to_vec());
    let wrap = |i: usize, n: usize| {
        let d = i.min(n - i) as f64;
        d * d
    };
    let (mut mass, mut second) = (0.0, 0.0);
    for (i, &v) in kernel.iter().enumerate() {
        let (r, c) = (i / gw, i % gw);
        mass += v;
        second += v * (wrap(r, gh) + wrap(c, gw));
    }
    if mass > 0.0 {
        (second / mass).max(0.0).sqrt()
    } else {
        0.0
    }
}
