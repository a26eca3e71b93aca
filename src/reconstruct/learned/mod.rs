//! The learned reconstruction (`--method learned`): Richardson-Lucy on the
//! time-summed stack for [`inputs::CHECKPOINTS`] iterations, then a small
//! multi-scale CNN ([`net`]) that corrects its last iterate from the
//! iterates, the counts, the light level and the blur width. The network
//! was trained here, on a 2-core CPU, on stacks the project's own forward
//! model simulated (`training/train_learned.py`); its weights are
//! embedded. A stack outside the ranges it was trained on is reconstructed
//! by the method it is given for them (Richardson-Lucy with its
//! cross-validated stop), and the notes say why. Like PnP, the output's Poisson deviance under the forward model
//! is in the trace.

pub mod inputs;
pub mod net;

use std::sync::OnceLock;

use ndarray::Array2;

use self::inputs::{CHECKPOINTS, denormalise, learned_inputs};
use self::net::LearnedNet;
use super::data::Data;
use super::discrepancy::ExpectedDeviance;
use super::em::RlStop;
use super::error::ReconstructError;
use super::rl_sum::RlSum;
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};

/// The embedded weights (trained by `training/train_learned.py`; its
/// metadata says how).
const EMBEDDED: &[u8] = include_bytes!("../../../weights/learned-unet2.safetensors");

/// The embedded network, read once.
pub fn embedded() -> &'static LearnedNet {
    static NET: OnceLock<LearnedNet> = OnceLock::new();
    NET.get_or_init(|| {
        LearnedNet::from_bytes(EMBEDDED, "the embedded learned weights")
            .expect("the embedded weights are checked by the tests")
    })
}

/// The learned reconstruction with `net`, and `outside` for stacks outside
/// its trained ranges.
pub struct Learned<'a> {
    /// The network.
    pub net: &'a LearnedNet,
    /// What reconstructs a stack outside the trained ranges.
    pub outside: Box<dyn Reconstructor + 'a>,
}

/// Richardson-Lucy on the time-summed stack with its cross-validated
/// stop: `--method learned`'s stand-in outside the trained ranges, and
/// the memory of the iterations that make the network's inputs.
pub const RL_SUM_CV: RlSum = RlSum {
    stop: RlStop::CROSS_VALIDATED,
};

/// Which method a [`Learned`] run used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Used {
    /// The network.
    Network,
    /// Its stand-in, the stack lying outside the trained ranges.
    Outside,
    /// Neither: the stack holds no photon (the output is 0).
    Neither,
}

impl Learned<'_> {
    /// Reconstructs with the network, or with `outside` when the stack
    /// lies outside the trained ranges (a note says why); which one ran.
    pub fn reconstruct_which(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<(Estimate, Used), ReconstructError> {
        let Some(inputs) = learned_inputs(data) else {
            return Ok((run.no_photons(data.model.sensor_shape()), Used::Neither));
        };
        if let Some(why) = self.net.outside(
            inputs.photons_per_pixel,
            inputs.kernel_width_px,
            inputs.background_share,
        ) {
            run.note(format!(
                "learned: the stack lies outside what the network was trained on: {why}; reconstructed by {} with its stop instead",
                self.outside.name(data.bins.len())
            ));
            return Ok((self.outside.reconstruct(data, run)?, Used::Outside));
        }
        let last = *CHECKPOINTS.last().expect("checkpoints");
        run.note(grid_note(data.model));
        run.note(format!(
            "learned: Richardson-Lucy on the time-summed stack, iterates {} fed with the scaled counts ({:.3} photons per pixel, blur RMS radius {:.2} px) to a {} network ({}; channels {:?})",
            CHECKPOINTS.map(|c| c.to_string()).join(", "),
            inputs.photons_per_pixel,
            inputs.kernel_width_px,
            net::ARCHITECTURE,
            self.net.meta("trained").unwrap_or("training run unrecorded"),
            self.net.channels,
        ));
        let output = self.net.forward(&inputs.features);
        let image = denormalise(&output, &inputs);
        if image.iter().any(|v| !v.is_finite()) {
            return Err(run.non_finite(last));
        }
        // The output's deviance: the network's object on the sensor window,
        // the last iterate beyond it.
        let model = data.model;
        let mut grid = inputs.base_grid;
        let (oy, ox) = model.sensor_offset();
        let (gh, gw) = model.grid_shape();
        for ((r, c), &v) in image.indexed_iter() {
            grid[(oy + r) * gw + ox + c] = v;
        }
        let grid = Array2::from_shape_vec((gh, gw), grid).expect("the model's grid");
        let check = ExpectedDeviance::shared().check(model, data.counts, data.bins, grid.view());
        let mut row = run.row(last);
        row.deviance = Some(check.deviance);
        row.expected_deviance = Some(check.expected);
        row.deviance_sd = Some(check.sd);
        run.score(&mut row, image.view());
        run.push(row);
        run.note(format!(
            "learned: output deviance {:.1}, Poisson noise alone {:.1} +- {:.1} (z = {:.1})",
            check.deviance,
            check.expected,
            check.sd,
            (check.deviance - check.expected) / check.sd.max(f64::MIN_POSITIVE)
        ));
        Ok((
            Estimate {
                image,
                iteration: last,
            },
            Used::Network,
        ))
    }
}

impl Reconstructor for Learned<'_> {
    fn name(&self, _bins: usize) -> &'static str {
        "learned"
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        self.reconstruct_which(data, run)
            .map(|(estimate, _)| estimate)
    }

    /// The larger of the stand-in's memory and the network's: the
    /// Richardson-Lucy iterations of its inputs, the inputs and the
    /// network's maps (at full resolution the padded input, two encoder
    /// and two decoder maps of `c0` channels and a concatenation of
    /// `c0 + c1`, about 100 floats per sensor pixel with the channels of
    /// the embedded network, counted as 160 (4 bytes each) for wider ones),
    /// and the convolutions' scratch per thread (which at 32 x 32 pixels
    /// outweighs the maps: 1.2-2.3 MB measured there, declared 2.8 MB).
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let network = RL_SUM_CV
            .working_bytes(shape)
            .saturating_add(shape.bytes([0; 3], [4 * 160, 8, 0]))
            .saturating_add(self.net.scratch_bytes(shape.grid.1));
        network.max(self.outside.working_bytes(shape))
    }
}
