//! The unrolled network's stages: the counts in every stage. From the last
//! Richardson-Lucy iterate (on the model's whole grid), each stage gives
//! the shared U-Net ([`LearnedNet::correction`]) the estimate, the log of
//! its EM ratio (where the counts ask for more or less light), the 10th and
//! 40th iterates, the scaled counts, the light level and the blur width;
//! adds the correction times the stage's weight to the estimate on the
//! sensor window, floored at [`FLOOR`] (an EM step cannot raise a zero);
//! then takes the network's exact EM steps through the time-summed
//! operator `reconstruct` uses (the sensor's edges, the background in the
//! denominator). The output is an EM iterate of the counts.

use ndarray::{Array3, Axis};

use super::inputs::{BASE_CHANNEL, LearnedInputs};
use super::net::{LearnedNet, STAGE_INPUTS};
use crate::forward::ForwardModel;
use crate::reconstruct::rl_sum::RlOperator;

/// The estimate's floor after a correction, in the inputs' scale.
pub const FLOOR: f64 = 1e-3;

/// The EM ratio's logarithm is clamped to plus or minus this.
const LOG_RATIO_CLAMP: f64 = 5.0;

/// Pixels whose sensitivity is at most this share of the kernel mass keep
/// their value in the stages' EM steps (the trainer's float32 transforms
/// cannot tell such a pixel's ratio from rounding; the two agree).
pub const UNSEEN: f64 = 1e-4;

/// The stages of `net` on `inputs` (of the counts `rl` sums), on the grid
/// of `model`: the output estimate on that grid.
pub(crate) fn run_stages(
    net: &LearnedNet,
    model: &ForwardModel,
    rl: &RlOperator,
    inputs: &LearnedInputs,
) -> Vec<f64> {
    let (_, h, w) = inputs.features.dim();
    let (oy, ox) = model.sensor_offset();
    let (_, gw) = model.grid_shape();
    let at = |r: usize, c: usize| (oy + r) * gw + ox + c;
    let scale = inputs.scale;
    let ratio = |x: &[f64]| rl.em_ratio(x, &inputs.counts, inputs.background, inputs.guard, UNSEEN);
    let mut x = inputs.base_grid.clone();
    let mut features = Array3::<f32>::zeros((STAGE_INPUTS, h, w));
    // The fixed channels: iterates before the last, counts, level, width.
    let fixed = (0..inputs.features.dim().0).filter(|&c| c != BASE_CHANNEL);
    for (to, from) in (2..STAGE_INPUTS).zip(fixed) {
        features
            .index_axis_mut(Axis(0), to)
            .assign(&inputs.features.index_axis(Axis(0), from));
    }
    for &weight in &net.stage_weights {
        let r = ratio(&x);
        for row in 0..h {
            for col in 0..w {
                let i = at(row, col);
                features[[0, row, col]] = (x[i] / scale) as f32;
                features[[1, row, col]] =
                    r[i].max(f64::MIN_POSITIVE)
                        .ln()
                        .clamp(-LOG_RATIO_CLAMP, LOG_RATIO_CLAMP) as f32;
            }
        }
        let correction = net.correction(&features);
        for ((row, col), &d) in correction.indexed_iter() {
            let i = at(row, col);
            x[i] = (x[i] / scale + f64::from(weight) * f64::from(d)).max(FLOOR) * scale;
        }
        for _ in 0..net.em_steps {
            let r = ratio(&x);
            x.iter_mut().zip(&r).for_each(|(v, f)| *v *= f.max(0.0));
        }
    }
    x
}
