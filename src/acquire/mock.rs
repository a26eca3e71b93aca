//! The emulated time tagger behind `--device mock` and `mock-serial`: its
//! set-up (scene, kernels, rates, faults), opening it on an in-process USB
//! transport or a pseudo-terminal, and its known scene as the sensor sees
//! it. Built with the `mock` feature (on by default); without it the types
//! exist but no mock can be made, and opening one says so.

#[cfg(feature = "mock")]
pub use emulated::*;

#[cfg(not(feature = "mock"))]
pub use absent::*;

#[cfg(feature = "mock")]
mod emulated {
    use ndarray::{Array2, Array3, s};
    use scatterscope_drivers::Link;
    use scatterscope_mocks::{Emitter, EmitterOptions, MockDevice, MockOptions};
    pub use scatterscope_mocks::{MockHandle, Truth};

    use super::super::device::{DeviceSpec, OpenError};
    use crate::forward::{Boundary, ForwardModel};
    use crate::physics::KernelStack;
    use crate::tags::binning::Region;

    /// IN-endpoint buffer of the in-process USB mock, in 512-byte packets.
    const MOCK_USB_BUFFER_PACKETS: usize = 1024;

    /// What a mock device emits.
    pub struct MockSetup {
        /// Scene intensity on the sensor grid.
        pub scene: Array2<f64>,
        /// ST-PSF kernels of the medium.
        pub kernels: KernelStack,
        /// Rates, sync period, delay, seed.
        pub emitter: EmitterOptions,
        /// Device behaviour (FIFO, pacing, faults).
        pub device: MockOptions,
    }

    /// Starts the mock `setup` behind `spec` (`mock` or `mock-serial`).
    pub(crate) fn open(
        spec: &DeviceSpec,
        setup: MockSetup,
    ) -> Result<(Link, MockHandle), OpenError> {
        let scene: Vec<f64> = setup.scene.iter().copied().collect();
        let period = setup.emitter.sync_period_ps;
        let emitter = Emitter::new(&scene, &setup.kernels, setup.emitter)
            .map_err(|e| OpenError::Mock(e.to_string()))?;
        let device = MockDevice::new(setup.device, emitter, period);
        if *spec == DeviceSpec::MockSerial {
            let (port, path) = scatterscope_mocks::pty::open().map_err(OpenError::Pty)?;
            let handle = device.spawn(Box::new(port));
            let mut link = scatterscope_drivers::serial::open(
                &path.to_string_lossy(),
                scatterscope_drivers::serial::DEFAULT_BAUD,
            )?;
            link.description = format!("mock-serial ({})", path.display());
            return Ok((link, handle));
        }
        let (port, ep_in, ep_out) = scatterscope_mocks::usb::endpoints(MOCK_USB_BUFFER_PACKETS);
        let handle = device.spawn(Box::new(port));
        let link = scatterscope_drivers::usb::link(
            "mock (in-process USB)".into(),
            Box::new(ep_in),
            Box::new(ep_out),
        );
        Ok((link, handle))
    }

    /// A mock's known scene as the sensor sees it: the expected stack at the
    /// set-up's light budget, to put a mock acquisition's reconstruction in
    /// the scene's units.
    pub struct MockReference {
        expected: Array3<f64>,
    }

    impl MockReference {
        /// The expected stack of `mock` (its sensor has edges and its scene is
        /// dark outside it).
        pub fn new(mock: &MockSetup) -> Self {
            let model = ForwardModel::new(&mock.kernels, Boundary::Sensor);
            Self {
                expected: model.expected_scene(mock.scene.view()).counts,
            }
        }

        /// The light budget that makes `binned` photons in `region` (dark counts
        /// removed, from the mock's truth) come out in the scene's units:
        /// `total_photons` scaled by the signal over its expectation. `None`
        /// when either is zero.
        pub fn light_budget(
            &self,
            total_photons: f64,
            region: Region,
            binned: u64,
            truth: &Truth,
        ) -> Option<f64> {
            let expected: f64 = self
                .expected
                .slice(s![
                    ..,
                    region.y..region.y + region.height,
                    region.x..region.x + region.width
                ])
                .sum();
            let dark_fraction = truth.dark_counts as f64 / truth.photons_detected.max(1) as f64;
            let signal = binned as f64 * (1.0 - dark_fraction);
            (expected > 0.0 && signal > 0.0).then(|| total_photons * signal / expected)
        }
    }
}

#[cfg(not(feature = "mock"))]
mod absent {
    use scatterscope_drivers::Link;

    use super::super::device::{DeviceSpec, OpenError};

    /// What a mock device emits: none in a build without the `mock` feature.
    pub enum MockSetup {}

    /// The running mock: none in a build without the `mock` feature.
    pub enum MockHandle {}

    /// There is no mock to open in this build.
    pub(crate) fn open(_: &DeviceSpec, setup: MockSetup) -> Result<(Link, MockHandle), OpenError> {
        match setup {}
    }
}
