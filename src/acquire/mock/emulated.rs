//! The emulated time tagger (the `mock` feature).

use ndarray::{Array2, Array3, s};
use scatterscope_drivers::Link;
use scatterscope_mocks::{Emitter, MockDevice};
pub use scatterscope_mocks::{EmitterOptions, Faults, MockHandle, MockOptions, Truth};

use super::super::ledger::Ledger;
use super::super::link::LinkSource;
use super::super::open_error::OpenError;
use super::super::source::{
    Delivery, Source, SourceEnd, SourceError, SourceFacts, SourceReport, StartRequest, StopReason,
    Until,
};
use crate::forward::{Boundary, ForwardModel};
use crate::physics::{KernelStack, Sampling, Setup};
use crate::scene::Scene;
use crate::tags::binning::Region;

/// IN-endpoint buffer of the in-process USB mock, in 512-byte packets.
const MOCK_USB_BUFFER_PACKETS: usize = 1024;

/// The most pixels a device of the wire protocol addresses (16-bit pixel
/// numbers).
pub const MAX_SENSOR_PIXELS: usize = firmware_protocol::record::MAX_PIXEL as usize + 1;

/// What `--device mock` images and how the emulated device behaves: the
/// settings a request gives it (the command line's mock flags are these
/// fields, their docs the flags' help); the rest of the device keeps the
/// mocks crate's defaults.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(
    feature = "cli",
    command(next_help_heading = "Mock device (--device mock, mock-serial)")
)]
pub struct MockSpec {
    /// The scene behind the medium (usaf, star, text, disks or an image).
    #[cfg_attr(feature = "cli", arg(long, default_value = "usaf", value_name = "SCENE|FILE", value_parser = |name: &str| Ok::<_, String>(Scene::parse(name))))]
    pub scene: Scene,
    /// Detected signal photons per second.
    #[cfg_attr(feature = "cli", arg(long = "rate", value_name = "RATE", default_value_t = EmitterOptions::default().rate_hz))]
    pub rate_hz: f64,
    /// Dark counts per second over the sensor.
    #[cfg_attr(feature = "cli", arg(long = "dark-rate", value_name = "DARK_RATE", default_value_t = EmitterOptions::default().dark_rate_hz))]
    pub dark_rate_hz: f64,
    /// Probability of an afterpulse (mean delay 50 ns) per detection.
    #[cfg_attr(feature = "cli", arg(long = "afterpulse", value_name = "AFTERPULSE", default_value_t = EmitterOptions::default().afterpulse_probability))]
    pub afterpulse_probability: f64,
    /// Random seed (same seed, same photons).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = EmitterOptions::default().seed))]
    pub seed: u64,
    /// Delay of the pulse after the laser sync (default unit ps).
    #[cfg_attr(feature = "cli", arg(long = "mock-delay", value_name = "MOCK_DELAY", default_value_t = EmitterOptions::default().t0_delay_ps, value_parser = crate::units::parse_ps))]
    pub t0_delay_ps: f64,
    /// Stop by itself after this many detected photons (0 = never).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = MockOptions::default().max_photons))]
    pub max_photons: u64,
    /// Emit in real time (`false`, the flag `--unpaced`: as fast as the
    /// link takes photons).
    #[cfg_attr(feature = "cli", arg(long = "unpaced", action = clap::ArgAction::SetFalse, help = "Emit as fast as the link takes photons instead of in real time"))]
    pub real_time: bool,
    /// Draw this many batches once and replay them (load tests at hardware
    /// rates). 0: draw every photon.
    #[cfg_attr(feature = "cli", arg(long = "mock-replay", value_name = "N", default_value_t = MockOptions::default().replay_batches))]
    pub replay_batches: usize,
    /// Faults every n-th batch, e.g. corrupt=10,duplicate=7,reorder=5,
    /// drop-bytes=9,overflow=4:1000,disconnect=50 (random=SEED: at random).
    #[cfg_attr(feature = "cli", arg(long, default_value = ""))]
    pub faults: Faults,
}

impl MockSpec {
    /// The image file the scene is read from, when it is one.
    pub fn scene_file(&self) -> Option<&std::path::Path> {
        match &self.scene {
            Scene::File(path) => Some(path),
            _ => None,
        }
    }

    /// The emitter's options: these settings over the mocks crate's
    /// defaults.
    pub fn emitter(&self) -> EmitterOptions {
        EmitterOptions {
            rate_hz: self.rate_hz,
            dark_rate_hz: self.dark_rate_hz,
            afterpulse_probability: self.afterpulse_probability,
            t0_delay_ps: self.t0_delay_ps,
            seed: self.seed,
            ..EmitterOptions::default()
        }
    }

    /// The device's options: these settings over the mocks crate's
    /// defaults.
    pub fn device(&self) -> MockOptions {
        MockOptions {
            real_time: self.real_time,
            max_photons: self.max_photons,
            faults: self.faults.clone(),
            replay_batches: self.replay_batches,
            ..MockOptions::default()
        }
    }
}

impl Default for MockSpec {
    /// The mocks crate's defaults, imaging the USAF target.
    fn default() -> Self {
        let (emitter, device) = (EmitterOptions::default(), MockOptions::default());
        Self {
            scene: Scene::parse("usaf"),
            rate_hz: emitter.rate_hz,
            dark_rate_hz: emitter.dark_rate_hz,
            afterpulse_probability: emitter.afterpulse_probability,
            seed: emitter.seed,
            t0_delay_ps: emitter.t0_delay_ps,
            max_photons: device.max_photons,
            real_time: device.real_time,
            replay_batches: device.replay_batches,
            faults: device.faults,
        }
    }
}

/// What a mock device emits, ready to start.
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

/// A running mock as an acquisition source: the link to it, and the
/// device's own counts to compare the host's with.
pub struct MockSource {
    link: LinkSource,
    handle: MockHandle,
    reference: MockReference,
    total_photons: f64,
    quota: u64,
    seed: u64,
}

impl MockSource {
    /// Starts the mock `setup` on an in-process USB transport, or behind a
    /// pseudo-terminal opened as a serial port (`serial`); `total_photons`
    /// is the set-up's light budget.
    pub fn open(setup: MockSetup, serial: bool, total_photons: f64) -> Result<Self, OpenError> {
        let reference = MockReference::new(&setup);
        let scene: Vec<f64> = setup.scene.iter().copied().collect();
        let period = setup.emitter.sync_period_ps;
        let (quota, seed) = (setup.device.max_photons, setup.emitter.seed);
        let emitter = Emitter::new(&scene, &setup.kernels, setup.emitter)
            .map_err(|e| OpenError::Mock(e.to_string()))?;
        let device = MockDevice::new(setup.device, emitter, period);
        let (link, handle): (Link, MockHandle) = if serial {
            let (port, path) = scatterscope_mocks::pty::open().map_err(OpenError::Pty)?;
            let handle = device.spawn(Box::new(port));
            let mut link = scatterscope_drivers::serial::open(
                &path.to_string_lossy(),
                scatterscope_drivers::serial::DEFAULT_BAUD,
            )?;
            link.description = format!("mock-serial ({})", path.display());
            (link, handle)
        } else {
            let (port, ep_in, ep_out) = scatterscope_mocks::usb::endpoints(MOCK_USB_BUFFER_PACKETS);
            let handle = device.spawn(Box::new(port));
            let link = scatterscope_drivers::usb::link(
                "mock (in-process USB)".into(),
                Box::new(ep_in),
                Box::new(ep_out),
            );
            (link, handle)
        };
        Ok(Self {
            link: LinkSource::new(link),
            handle,
            reference,
            total_photons,
            quota,
            seed,
        })
    }

    /// Waits for the device thread to end (after the stream) and returns
    /// its final counts.
    pub fn join(self) -> Truth {
        drop(self.link);
        self.handle.join()
    }
}

impl Source for MockSource {
    fn start(&mut self, request: &StartRequest) -> Result<SourceFacts, SourceError> {
        self.link.start(request)
    }

    fn stream(&mut self, until: Until<'_>, sink: &mut dyn FnMut(Delivery<'_>)) -> SourceEnd {
        self.link.stream(until, sink)
    }

    fn report(&self, ledger: &Ledger, region: Option<Region>, stop: &StopReason) -> SourceReport {
        let t = self.handle.truth();
        let mut notes = Vec::new();
        if *stop == StopReason::Duration && self.quota > 0 && ledger.counts.photons < self.quota {
            notes.push(format!(
                "note: the duration ended the acquisition before the mock's photon quota ({}) was reached; without a duration it runs until the device stops",
                self.quota
            ));
        }
        notes.push(format!(
            "mock truth: detected {} ({} dark, {} afterpulses), lost in FIFO {}, damaged in transit {}, never sent {}",
            t.photons_detected,
            t.dark_counts,
            t.afterpulses,
            t.photons_lost_fifo,
            t.photons_damaged,
            t.photons_unsent
        ));
        let light_budget = region.and_then(|r| {
            self.reference
                .light_budget(self.total_photons, r, ledger.counts.binned, &t)
        });
        SourceReport {
            notes,
            light_budget,
            seed: Some(self.seed),
        }
    }
}

/// Opens the mock `spec` with the physics of `setup` (its sensor, medium
/// and window): the source, and the scene as the sensor sees it (the
/// truth a reconstruction is judged against).
pub(crate) fn open_spec(
    spec: &MockSpec,
    serial: bool,
    setup: &Setup,
) -> Result<(Box<dyn Source>, Array2<f64>), OpenError> {
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    if h * w > MAX_SENSOR_PIXELS {
        return Err(OpenError::SensorTooLarge {
            width: w,
            height: h,
            max: MAX_SENSOR_PIXELS,
        });
    }
    crate::memory::check_setup(setup, crate::memory::PSF_BYTES, "the mock's kernels")
        .map_err(|e| OpenError::Mock(e.to_string()))?;
    let truth = spec
        .scene
        .render(h, w)
        .map_err(|e| OpenError::Mock(e.to_string()))?;
    let kernels = KernelStack::build(setup, Sampling::Integrated)
        .map_err(|e| OpenError::Mock(e.to_string()))?;
    let source = MockSource::open(
        MockSetup {
            scene: truth.clone(),
            kernels,
            emitter: spec.emitter(),
            device: spec.device(),
        },
        serial,
        setup.total_photons,
    )?;
    Ok((Box::new(source), truth))
}

/// The scene of `spec` on the sensor of `setup` (`None` when it does not
/// render there).
pub(crate) fn scene_truth(spec: &MockSpec, setup: &Setup) -> Option<Array2<f64>> {
    spec.scene
        .render(setup.sensor.height_px, setup.sensor.width_px)
        .ok()
}

/// A mock's known scene as the sensor sees it: the expected stack at the
/// set-up's light budget, to put a mock acquisition's reconstruction in
/// the scene's units.
struct MockReference {
    expected: Array3<f64>,
}

impl MockReference {
    /// The expected stack of `mock` (its sensor has edges and its scene is
    /// dark outside it).
    fn new(mock: &MockSetup) -> Self {
        let model = ForwardModel::new(&mock.kernels, Boundary::Sensor);
        Self {
            expected: model.expected_scene(mock.scene.view()).counts,
        }
    }

    /// The light budget that makes `binned` photons in `region` (dark
    /// counts removed, from the mock's truth) come out in the scene's
    /// units: `total_photons` scaled by the signal over its expectation.
    /// `None` when either is zero.
    fn light_budget(
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
