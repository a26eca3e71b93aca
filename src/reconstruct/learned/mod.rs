//! The learned reconstruction (`--method learned`): Richardson-Lucy on the
//! time-summed stack for [`inputs::CHECKPOINTS`] iterations, then an
//! unrolled network with the counts in every stage ([`stages`]): a small
//! multi-scale CNN ([`net`]), shared by the stages, corrects the estimate
//! from its EM ratio, the iterates, the counts, the light level and the
//! blur width, and exact EM steps through the reconstruction's own
//! operator follow each correction, so the output is an EM iterate of the
//! counts. The network was trained here, on a 2-core CPU, on stacks
//! simulated with more than one discretisation of the physics
//! (`training/train_unrolled.py`); its weights are embedded, and weights a
//! user trained are read by [`from_file`]. A stack
//! outside the ranges it was trained on is reconstructed by the method it
//! is given for them, and the notes say why. The output's Poisson
//! deviance under the forward model is in the trace.

pub mod inputs;
pub mod net;
pub mod stages;

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use ndarray::Array2;

use self::inputs::{CHECKPOINTS, LearnedInputs, kernel_rms_radius, learned_inputs};
use self::net::{LearnedNet, NetError};
use super::data::Data;
use super::discrepancy::{DevianceCheck, ExpectedDeviance};
use super::em::RlStop;
use super::error::ReconstructError;
use super::rl_sum::{RlOperator, RlSum};
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};

/// The embedded weights (trained by `training/train_unrolled.py`; its
/// metadata says how).
const EMBEDDED: &[u8] = include_bytes!("../../../weights/learned-unrolled.safetensors");

/// The embedded network, read once.
pub fn embedded() -> &'static LearnedNet {
    static NET: OnceLock<LearnedNet> = OnceLock::new();
    NET.get_or_init(|| {
        LearnedNet::from_bytes(EMBEDDED, "the embedded learned weights")
            .expect("the embedded weights are checked by the tests")
    })
}

/// The network in the weights file at `path` (as
/// `training/train_unrolled.py` writes it), read once per process and
/// content: reading a file whose bytes are unchanged returns the network
/// read before, and a rewritten file is read anew. Every network read is
/// kept until the process ends (a few hundred kilobytes each), so that
/// [`super::method::MethodOptions`] can hold it.
pub fn from_file(path: &Path) -> Result<&'static LearnedNet, NetError> {
    type Registry = Mutex<HashMap<(PathBuf, u64), &'static LearnedNet>>;
    static READ: OnceLock<Registry> = OnceLock::new();
    let origin = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| NetError {
        origin: origin.clone(),
        problem: format!("cannot be read: {e}"),
    })?;
    let mut hasher = std::hash::DefaultHasher::new();
    bytes.hash(&mut hasher);
    let key = (path.to_path_buf(), hasher.finish());
    let mut read = READ
        .get_or_init(Registry::default)
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(net) = read.get(&key) {
        return Ok(net);
    }
    let net: &'static LearnedNet = Box::leak(Box::new(LearnedNet::from_bytes(&bytes, &origin)?));
    read.insert(key, net);
    Ok(net)
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

/// The network's output on a stack, with its deviance on the whole stack.
pub struct NetworkOutput {
    /// The estimate on the sensor.
    pub estimate: Estimate,
    /// The estimate on the model's grid.
    pub grid: Array2<f64>,
    /// Its deviance against every bin, and Poisson noise's.
    pub check: DevianceCheck,
}

impl Learned<'_> {
    /// Why `data` lies outside the network's trained ranges (light, blur
    /// width, background), by name; `None` inside or without photons.
    pub fn outside_why(&self, data: &Data<'_>) -> Option<String> {
        let (h, w) = data.model.sensor_shape();
        let total = data.counts.sum();
        if total <= 0.0 {
            return None;
        }
        let photons_per_pixel = total / (h * w) as f64;
        let background = data.model.background() * data.bins.len() as f64;
        let width = kernel_rms_radius(&data.model.summed(data.bins));
        self.net
            .outside(photons_per_pixel, width, background / photons_per_pixel)
    }

    /// Reconstructs with the network, or with `outside` when the stack
    /// lies outside the trained ranges (a note says why); which one ran.
    pub fn reconstruct_which(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<(Estimate, Used), ReconstructError> {
        if let Some(why) = self.outside_why(data) {
            run.note(format!(
                "learned: the stack lies outside what the network was trained on: {why}; reconstructed by {} with its stop instead",
                self.outside.name(data.bins.len())
            ));
            return Ok((self.outside.reconstruct(data, run)?, Used::Outside));
        }
        match self.network(data, run)? {
            Some(out) => Ok((out.estimate, Used::Network)),
            None => Ok((run.no_photons(data.model.sensor_shape()), Used::Neither)),
        }
    }

    /// The network on `data` (no range check), its output's deviance in
    /// the trace and the notes; `None` without photons.
    pub fn network(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Option<NetworkOutput>, ReconstructError> {
        let Some(inputs) = learned_inputs(data) else {
            return Ok(None);
        };
        let last = *CHECKPOINTS.last().expect("checkpoints");
        run.note(grid_note(data.model));
        run.note(format!(
            "learned: Richardson-Lucy on the time-summed stack, iterates {} with the scaled counts ({:.3} photons per pixel, blur RMS radius {:.2} px) into a {} network of {} stages, each a shared CNN's correction and {} exact EM steps ({}; channels {:?})",
            CHECKPOINTS.map(|c| c.to_string()).join(", "),
            inputs.photons_per_pixel,
            inputs.kernel_width_px,
            net::ARCHITECTURE,
            self.net.stages,
            self.net.em_steps,
            self.net.meta("trained").unwrap_or("training run unrecorded"),
            self.net.channels,
        ));
        let grid = network_estimate(self.net, data, &inputs);
        if grid.iter().any(|v| !v.is_finite()) {
            return Err(run.non_finite(last));
        }
        let model = data.model;
        let image = Array2::from_shape_vec(model.sensor_shape(), model.crop_vec(&grid))
            .expect("the sensor's window");
        let grid = Array2::from_shape_vec(model.grid_shape(), grid).expect("the model's grid");
        let check = ExpectedDeviance::shared().check(model, data.counts, data.bins, grid.view());
        let iteration = last + self.net.stages * self.net.em_steps;
        let mut row = run.row(iteration);
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
            check.z()
        ));
        Ok(Some(NetworkOutput {
            estimate: Estimate { image, iteration },
            grid,
            check,
        }))
    }
}

/// The network's estimate of `data`, whose inputs are `inputs`, on the
/// model's grid: the stages from the last Richardson-Lucy iterate, with no
/// range check and no stand-in.
pub fn network_estimate(net: &LearnedNet, data: &Data<'_>, inputs: &LearnedInputs) -> Vec<f64> {
    let rl = RlOperator::new(data.model, data.bins);
    stages::run_stages(net, data.model, &rl, inputs)
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
    /// Richardson-Lucy iterations of its inputs, the inputs and a stage's
    /// maps (at full resolution the padded input, two encoder and two
    /// decoder maps of `c0` channels and a concatenation of `c0 + c1`,
    /// about 100 floats per sensor pixel with the channels of the embedded
    /// network, counted as 160 (4 bytes each) for wider ones, and the
    /// stage's 7 input channels), the stages' estimate, EM ratio and
    /// transforms on the grid (5 more vectors of f64), and the
    /// convolutions' scratch per thread (which at 32 x 32 pixels outweighs
    /// the maps: 1.2-2.3 MB measured there, declared 2.8 MB).
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let network = RL_SUM_CV
            .working_bytes(shape)
            .saturating_add(shape.bytes([0; 3], [4 * 167, 48, 0]))
            .saturating_add(self.net.scratch_bytes(shape.grid.1));
        network.max(self.outside.working_bytes(shape))
    }
}
