//! One acquisition as every front end asks for it: the command line, the
//! Python package and scripts build a [`Request`] from what the user gave,
//! and [`Request::job`] checks it once and makes it the [`Job`] that runs.
//! Every device default and refusal lives here: the duration a device
//! runs by default, the settings only a PicoQuant device takes (refused by
//! name for any other, which would ignore them), the units a vendor's
//! library takes them in, the PTU a vendor's device records by default,
//! and the window a stack is binned into.

use std::path::PathBuf;
use std::time::Duration;

use super::DeviceSpec;
use super::job::{Job, TimeZero};
use super::mock::MockSpec;
use super::picoquant::{PicoQuantDevice, SettingsRequest};
use super::pipeline::{AcquireError, StreamPlan, resolution_fs};
use super::replay::ReplaySpec;
use crate::config::{ConfigError, PhysicsOverrides};
use crate::events::Imaging;
use crate::tags::bin_file::Pixels;
use crate::tags::binning::Region;

/// How long an acquisition runs when the request does not say (a replay
/// runs to the end of its recording).
pub const DEFAULT_DURATION: Duration = Duration::from_secs(2);

/// One acquisition, as asked for. [`Request::new`] holds the defaults of
/// every setting (those of `scatterscope acquire`, whose flags are these
/// fields: their docs are the flags' help).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct Request {
    /// The device: mock (in-process USB), mock-serial (pseudo-terminal),
    /// serial:PATH, usb:VID:PID[:SERIAL], picoquant[:FAMILY][:SERIAL]
    /// (FAMILY multiharp, hydraharp, timeharp260, picoharp330 or picoharp
    /// for the PicoHarp 300, through the vendor's library), or
    /// replay:FILE (a PTU or tag file played back at its recorded pace,
    /// e.g. with --live to review a run); see `scatterscope devices`.
    #[cfg_attr(feature = "cli", arg(long, default_value = "mock"))]
    pub device: DeviceSpec,
    /// How long to acquire (e.g. 10s, 500ms, 2m); 0 runs until the device
    /// stops or is stopped (Ctrl-C). [default: 2s; a replay: the whole
    /// recording]
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::units::parse_duration))]
    pub duration: Option<Duration>,
    /// The sample's physics as given (preset, file, values). A device
    /// whose sensor is the image (ours, the mocks) bins into the window
    /// they resolve to and records them with the stack; a vendor's device
    /// or a recording takes only the window given (`bin_width`, `t_start`,
    /// `bins`; by default one sync period at the device's unit), and no
    /// physics are assumed for it.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub physics: PhysicsOverrides,
    /// Time zero (the command line's --t0 or --t0-from).
    #[cfg_attr(feature = "cli", arg(skip = TimeZero::At(0.0)))]
    pub t0: TimeZero,
    /// Bin only this region of the sensor: X,Y,WIDTH,HEIGHT in pixels
    /// (default: the whole sensor).
    #[cfg_attr(feature = "cli", arg(long = "roi", value_name = "ROI"))]
    pub region: Option<Region>,
    /// Micro-time unit of our own devices to configure (default: the
    /// device's TDC resolution; --binning sets a PicoQuant device's).
    #[cfg_attr(feature = "cli", arg(long = "micro-time-unit", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub micro_time_unit_ps: Option<f64>,
    /// Also record every event batch losslessly to this tag file (.sstags).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub tags: Option<PathBuf>,
    /// With --device replay:FILE: play the recording this many times faster
    /// than it was recorded (1 for every other device).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "FACTOR", default_value_t = 1.0)
    )]
    pub speed: f64,
    /// Also write the stack as OME-TIFF (stack.ome.tif: one page per bin,
    /// the bins as the lifetime axis, counts as integers) for Fiji,
    /// napari or FLIMfit.
    #[cfg_attr(feature = "cli", arg(long))]
    pub ome_tiff: bool,
    /// Output directory (created if missing).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/acquire"))]
    pub out: PathBuf,
    /// The software named in the outputs.
    #[cfg_attr(feature = "cli", arg(skip = software()))]
    pub software: String,
    /// The mock's scene and behaviour (used by the mock devices only).
    #[cfg_attr(feature = "cli", command(flatten))]
    pub mock: MockSpec,
    /// What only a PicoQuant device takes.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub picoquant: PicoQuantRequest,
}

/// This build, as the outputs name it.
fn software() -> String {
    format!("scatterscope {}", env!("CARGO_PKG_VERSION"))
}

/// The settings only a PicoQuant device takes, in the units a user gives
/// them (ps, mV); unset ones take the vendor demos' values. The command
/// line's PicoQuant flags are these fields (their docs are the flags'
/// help). The stack's window is --bin-width, --t-start and --bins
/// (default: the device's micro-time unit over one sync period).
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(feature = "cli", command(next_help_heading = "PicoQuant devices"))]
pub struct PicoQuantRequest {
    /// The vendor library file (default: the family's variable,
    /// $SCATTERSCOPE_MHLIB, _HHLIB, _TH260LIB, _PH330LIB or _PHLIB, then
    /// the installer's libmh150.so, libhh400.so, libth260.so, libph330.so
    /// or libph300.so and /usr/local/lib64/{mh150,hh400,th260,ph330,ph300}/).
    #[cfg_attr(feature = "cli", arg(long = "vendor-lib", value_name = "FILE"))]
    pub library: Option<PathBuf>,
    /// Sync divider.
    #[cfg_attr(feature = "cli", arg(long, value_name = "N"))]
    pub sync_divider: Option<i32>,
    /// Sync trigger level (edge-trigger boards) or CFD level (HydraHarp, TimeHarp 260 Pico, PicoHarp 300), mV.
    #[cfg_attr(
        feature = "cli",
        arg(long = "sync-level", value_name = "MV", allow_negative_numbers = true)
    )]
    pub sync_level_mv: Option<i32>,
    /// Sync trigger edge (MultiHarp, TimeHarp 260 Nano, PicoHarp 330): rising or falling.
    #[cfg_attr(feature = "cli", arg(long = "sync-edge", value_name = "EDGE", value_parser = parse_edge))]
    pub sync_rising: Option<bool>,
    /// The scan markers' active edge, rising or falling [default: rising].
    #[cfg_attr(feature = "cli", arg(long = "marker-edge", value_name = "EDGE", value_parser = parse_edge, requires = "scan"))]
    pub markers_rising: Option<bool>,
    /// Sync CFD zero cross (HydraHarp, TimeHarp 260 Pico, PicoHarp 300), mV.
    #[cfg_attr(feature = "cli", arg(long = "sync-zero-cross", value_name = "MV"))]
    pub sync_zero_cross_mv: Option<i32>,
    /// Sync channel offset (default unit ps; a PicoHarp 300's sync offset).
    #[cfg_attr(feature = "cli", arg(long = "sync-offset", value_name = "TIME", value_parser = crate::units::parse_ps, allow_negative_numbers = true))]
    pub sync_offset_ps: Option<f64>,
    /// Input trigger level (edge-trigger boards) or CFD level (CFD boards), mV; every input.
    #[cfg_attr(
        feature = "cli",
        arg(long = "input-level", value_name = "MV", allow_negative_numbers = true)
    )]
    pub input_level_mv: Option<i32>,
    /// Input trigger edge (MultiHarp, TimeHarp 260 Nano, PicoHarp 330): rising or falling.
    #[cfg_attr(feature = "cli", arg(long = "input-edge", value_name = "EDGE", value_parser = parse_edge))]
    pub input_rising: Option<bool>,
    /// Input CFD zero cross (HydraHarp, TimeHarp 260 Pico, PicoHarp 300), mV.
    #[cfg_attr(feature = "cli", arg(long = "input-zero-cross", value_name = "MV"))]
    pub input_zero_cross_mv: Option<i32>,
    /// Per-input offsets, comma-separated (default unit ps), e.g. 0,120ps
    /// (none on a PicoHarp 300).
    #[cfg_attr(feature = "cli", arg(long = "input-offsets", value_name = "TIMES", value_delimiter = ',', value_parser = crate::units::parse_ps, allow_negative_numbers = true))]
    pub input_offsets_ps: Vec<f64>,
    /// Binning code: micro-time unit = base resolution x 2^N (0 to 7 on a
    /// PicoHarp 300).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N"))]
    pub binning: Option<i32>,
    /// T3 offset: a time with its unit (e.g. 10ns); the device takes whole
    /// nanoseconds.
    #[cfg_attr(feature = "cli", arg(long = "t3-offset", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub t3_offset_ps: Option<f64>,
    /// A galvo scan of WxH points clocked by markers 1 (line start), 2
    /// (line stop) and 3 (frame); the stack is its image.
    #[cfg_attr(feature = "cli", arg(long, value_name = "WxH", value_parser = parse_scan))]
    pub scan: Option<Imaging>,
    /// Keep only photons of this input (as numbered in the records).
    #[cfg_attr(feature = "cli", arg(long))]
    pub channel: Option<u16>,
    /// Pixel mapping: auto (the scan's image, else single), single, channel.
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<Pixels>(), default_value = crate::Named::name(Pixels::default())))]
    pub pixels: Pixels,
    /// Write every record to this PTU file (a PicoQuant device: default
    /// OUT/acquisition.ptu; our own devices and the mocks: Generic T3 with
    /// the sensor pixel as the input channel, sensors of at most 63
    /// pixels).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub ptu: Option<PathBuf>,
    /// Do not write a PTU file (PicoQuant devices).
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "ptu"))]
    pub no_ptu: bool,
}

impl PicoQuantRequest {
    /// The settings given, by their command-line names.
    fn given(&self) -> Vec<&'static str> {
        let set = [
            ("--vendor-lib", self.library.is_some()),
            ("--sync-divider", self.sync_divider.is_some()),
            ("--sync-level", self.sync_level_mv.is_some()),
            ("--sync-edge", self.sync_rising.is_some()),
            ("--marker-edge", self.markers_rising.is_some()),
            ("--sync-zero-cross", self.sync_zero_cross_mv.is_some()),
            ("--sync-offset", self.sync_offset_ps.is_some()),
            ("--input-level", self.input_level_mv.is_some()),
            ("--input-edge", self.input_rising.is_some()),
            ("--input-zero-cross", self.input_zero_cross_mv.is_some()),
            ("--input-offsets", !self.input_offsets_ps.is_empty()),
            ("--binning", self.binning.is_some()),
            ("--t3-offset", self.t3_offset_ps.is_some()),
            ("--scan", self.scan.is_some()),
            ("--channel", self.channel.is_some()),
            ("--pixels", self.pixels != Pixels::Auto),
            ("--no-ptu", self.no_ptu),
        ];
        set.into_iter()
            .filter(|(_, on)| *on)
            .map(|(f, _)| f)
            .collect()
    }

    /// The library's settings: offsets in the whole units it takes.
    fn settings(&self) -> Result<SettingsRequest, RequestError> {
        Ok(SettingsRequest {
            sync_divider: self.sync_divider,
            sync_level_mv: self.sync_level_mv,
            sync_rising: self.sync_rising,
            sync_zero_cross_mv: self.sync_zero_cross_mv,
            sync_offset_ps: self
                .sync_offset_ps
                .map(|v| whole(v, WHOLE_PS, "sync-offset"))
                .transpose()?,
            input_level_mv: self.input_level_mv,
            input_rising: self.input_rising,
            markers_rising: self.markers_rising,
            input_zero_cross_mv: self.input_zero_cross_mv,
            input_offsets_ps: self
                .input_offsets_ps
                .iter()
                .map(|&v| whole(v, WHOLE_PS, "input-offsets"))
                .collect::<Result<_, _>>()?,
            binning: self.binning,
            t3_offset_ns: self
                .t3_offset_ps
                .map(|v| whole(v, WHOLE_NS, "t3-offset"))
                .transpose()?,
        })
    }
}

/// An edge by name: `rising` (true) or `falling`.
pub fn parse_edge(s: &str) -> Result<bool, String> {
    match s {
        "rising" => Ok(true),
        "falling" => Ok(false),
        _ => Err(format!("edge `{s}`: use rising or falling")),
    }
}

/// A scan's points, `WIDTHxHEIGHT` (e.g. `64x64`), with the markers the
/// PicoQuant demos use (line start 1, line stop 2, frame 4; one way).
pub fn parse_scan(s: &str) -> Result<Imaging, String> {
    let bad = || format!("scan `{s}`: give WIDTHxHEIGHT in points, e.g. 64x64");
    let (w, h) = s.split_once('x').ok_or_else(bad)?;
    let (w, h): (usize, usize) = (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
    if w == 0 || h == 0 {
        return Err(bad());
    }
    Ok(Imaging {
        pixels_x: w,
        pixels_y: h,
        line_start: 1,
        line_stop: 2,
        frame: 4,
        bidirectional: false,
    })
}

/// A unit a vendor's library takes offsets in whole: its size in ps and
/// its name in an error.
type WholeUnit = (f64, &'static str);
/// Whole picoseconds.
const WHOLE_PS: WholeUnit = (1.0, "picoseconds");
/// Whole nanoseconds.
const WHOLE_NS: WholeUnit = (1000.0, "nanoseconds (e.g. 10ns)");

/// `v_ps` in whole `unit`s, as the vendor's library takes `setting`.
fn whole(
    v_ps: f64,
    (unit_ps, unit): WholeUnit,
    setting: &'static str,
) -> Result<i32, RequestError> {
    let v = v_ps / unit_ps;
    let r = v.round();
    if (r - v).abs() < 1e-9 && r.abs() <= f64::from(i32::MAX) {
        Ok(r as i32)
    } else {
        Err(RequestError::NotWhole {
            setting,
            value_ps: v_ps,
            unit,
        })
    }
}

/// Why a request cannot run.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// Settings only a PicoQuant device takes, for another device.
    #[error("{} set a PicoQuant device (--device picoquant); {device} would ignore them", given.join(", "))]
    PicoQuantOnly {
        /// The settings given, by their command-line names.
        given: Vec<&'static str>,
        /// The device asked for.
        device: String,
    },
    /// An offset the vendor's library takes in whole units.
    #[error("--{setting} {value_ps} ps: the device takes whole {unit}")]
    NotWhole {
        /// The setting.
        setting: &'static str,
        /// Its value, ps.
        value_ps: f64,
        /// The unit it must be whole in.
        unit: &'static str,
    },
    /// A replay speed for a device that is not a replay.
    #[error(
        "--speed plays a recording back faster (--device replay:FILE); {device} runs at its own pace"
    )]
    SpeedNotReplay {
        /// The device asked for.
        device: String,
    },
    /// A duration past what the vendor's library measures.
    #[error(
        "--duration {hours:.1} h: a PicoQuant measurement lasts at most 100 h (ACQTMAX 360000000 ms in the vendor's headers); give at most 100h, or 0 to run until stopped"
    )]
    DurationTooLong {
        /// The duration asked, hours.
        hours: f64,
    },
    /// The physics given do not resolve.
    #[error(transparent)]
    Physics(#[from] ConfigError),
    /// A setting out of range.
    #[error(transparent)]
    Setting(#[from] AcquireError),
}

impl Request {
    /// A request for `device` writing into `out`, every other setting at
    /// its default.
    pub fn new(device: DeviceSpec, out: PathBuf) -> Self {
        Self {
            device,
            duration: None,
            physics: PhysicsOverrides::default(),
            t0: TimeZero::At(0.0),
            region: None,
            micro_time_unit_ps: None,
            tags: None,
            speed: 1.0,
            ome_tiff: false,
            out,
            software: software(),
            mock: MockSpec::default(),
            picoquant: PicoQuantRequest::default(),
        }
    }

    /// Checks the request and makes it the job that runs, with the notes
    /// resolving its physics gave (a reference recording's instrument
    /// response). Refuses by name a setting the device cannot take,
    /// before the device is touched.
    pub fn job(&self) -> Result<(Job, Vec<String>), RequestError> {
        let (device, mut plan) = self.device_and_plan()?;
        let mut notes = Vec::new();
        let setup = if device.is_sensor() {
            let (setup, resolved) = self.physics.resolve_noted(None)?;
            notes = resolved;
            plan.set_window(&setup.bins);
            Some(setup)
        } else {
            // A vendor's device or its recording: the window given
            // (default: one sync period); its physics are not assumed.
            plan.bin_width_ps = self.physics.bin_width;
            plan.t_start_ps = self.physics.t_start.unwrap_or(0.0);
            plan.bins = self.physics.bins;
            None
        };
        Ok((
            Job {
                device,
                setup,
                t0: self.t0.clone(),
                plan,
                out: self.out.clone(),
                ome_tiff: self.ome_tiff,
            },
            notes,
        ))
    }

    /// Every device rule [`Self::job`] applies, without reading the
    /// physics' files (a reference recording or a configuration an earlier
    /// job of a batch may still have to write); the device untouched.
    pub fn check(&self) -> Result<(), RequestError> {
        self.device_and_plan().map(|_| ())
    }

    /// The device as configured and the stream's plan before its window:
    /// the device rules checked.
    fn device_and_plan(&self) -> Result<(DeviceSpec, StreamPlan), RequestError> {
        let p = &self.picoquant;
        let mut plan = StreamPlan {
            region: self.region,
            channel: p.channel,
            pixels: p.pixels,
            duration: match (self.duration, &self.device) {
                (Some(d), _) => (!d.is_zero()).then_some(d),
                (None, DeviceSpec::Replay(_)) => None,
                (None, _) => Some(DEFAULT_DURATION),
            },
            resolution_fs: self.micro_time_unit_ps.map(resolution_fs).transpose()?,
            tag_file: self.tags.clone(),
            ptu: p.ptu.clone(),
            software: self.software.clone(),
            ..StreamPlan::default()
        };
        let device = match &self.device {
            DeviceSpec::PicoQuant(d) => {
                let longest = super::picoquant::MAX_MEASUREMENT_MS as u128;
                if let Some(d) = plan.duration.filter(|d| d.as_millis() > longest) {
                    return Err(RequestError::DurationTooLong {
                        hours: d.as_secs_f64() / 3600.0,
                    });
                }
                // The vendor's device: its settings and a PTU by default.
                if !p.no_ptu && plan.ptu.is_none() {
                    plan.ptu = Some(self.out.join("acquisition.ptu"));
                }
                DeviceSpec::PicoQuant(PicoQuantDevice {
                    spec: d.spec.clone(),
                    library: p.library.clone(),
                    settings: p.settings()?,
                    scan: p.scan,
                })
            }
            other => {
                let given = p.given();
                if !given.is_empty() {
                    return Err(RequestError::PicoQuantOnly {
                        given,
                        device: other.to_string(),
                    });
                }
                match other {
                    DeviceSpec::Mock(_) => DeviceSpec::Mock(self.mock.clone()),
                    DeviceSpec::MockSerial(_) => DeviceSpec::MockSerial(self.mock.clone()),
                    DeviceSpec::Replay(r) => DeviceSpec::Replay(ReplaySpec {
                        path: r.path.clone(),
                        speed: self.speed,
                    }),
                    hardware => hardware.clone(),
                }
            }
        };
        if self.speed != 1.0 && !matches!(device, DeviceSpec::Replay(_)) {
            return Err(RequestError::SpeedNotReplay {
                device: device.to_string(),
            });
        }
        Ok((device, plan))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(device: &str) -> Request {
        Request::new(device.parse().unwrap(), PathBuf::from("out/x"))
    }

    #[test]
    fn a_device_runs_two_seconds_by_default_a_replay_to_its_end_and_zero_until_stopped() {
        let (job, _) = request("mock").job().unwrap();
        assert_eq!(job.plan.duration, Some(DEFAULT_DURATION));
        let (job, _) = request("replay:run.ptu").job().unwrap();
        assert_eq!(job.plan.duration, None);
        let mut r = request("mock");
        r.duration = Some(Duration::ZERO);
        assert_eq!(r.job().unwrap().0.plan.duration, None);
        r.duration = Some(Duration::from_millis(500));
        assert_eq!(
            r.job().unwrap().0.plan.duration,
            Some(Duration::from_millis(500))
        );
    }

    #[test]
    fn picoquant_settings_are_refused_by_name_for_any_other_device() {
        let mut r = request("mock");
        r.picoquant.sync_level_mv = Some(-50);
        r.picoquant.t3_offset_ps = Some(10_000.0);
        r.picoquant.pixels = Pixels::Channel;
        let e = r.job().unwrap_err().to_string();
        assert_eq!(
            e,
            "--sync-level, --t3-offset, --pixels set a PicoQuant device (--device picoquant); mock would ignore them"
        );
        for device in ["mock-serial", "replay:run.ptu", "serial:/dev/ttyACM0"] {
            let mut r = request(device);
            r.picoquant.no_ptu = true;
            assert!(r.job().unwrap_err().to_string().starts_with("--no-ptu set"));
        }
    }

    #[test]
    fn offsets_go_to_the_library_in_its_whole_units_or_are_refused() {
        let mut r = request("picoquant");
        r.picoquant.t3_offset_ps = Some(10_000.0);
        r.picoquant.sync_offset_ps = Some(-25.0);
        r.picoquant.input_offsets_ps = vec![0.0, 12.0];
        let (job, _) = r.job().unwrap();
        let DeviceSpec::PicoQuant(d) = &job.device else {
            panic!("{:?}", job.device)
        };
        assert_eq!(d.settings.t3_offset_ns, Some(10));
        assert_eq!(d.settings.sync_offset_ps, Some(-25));
        assert_eq!(d.settings.input_offsets_ps, vec![0, 12]);
        r.picoquant.t3_offset_ps = Some(10_500.0);
        assert_eq!(
            r.job().unwrap_err().to_string(),
            "--t3-offset 10500 ps: the device takes whole nanoseconds (e.g. 10ns)"
        );
        r.picoquant.t3_offset_ps = None;
        r.picoquant.input_offsets_ps = vec![0.5];
        assert_eq!(
            r.job().unwrap_err().to_string(),
            "--input-offsets 0.5 ps: the device takes whole picoseconds"
        );
    }

    #[test]
    fn a_vendors_device_records_a_ptu_by_default_and_takes_only_the_window() {
        let mut r = request("picoquant:hydraharp");
        r.physics.bin_width = Some(8.0);
        r.physics.bins = Some(100);
        let (job, _) = r.job().unwrap();
        assert_eq!(job.plan.ptu, Some(PathBuf::from("out/x/acquisition.ptu")));
        assert!(job.setup.is_none());
        assert_eq!(
            (job.plan.bin_width_ps, job.plan.bins),
            (Some(8.0), Some(100))
        );
        r.picoquant.no_ptu = true;
        assert_eq!(r.job().unwrap().0.plan.ptu, None);
        // A sensor device bins into the window its physics resolve to.
        let (job, _) = request("mock").job().unwrap();
        let setup = job.setup.unwrap();
        assert_eq!(job.plan.bin_width_ps, Some(setup.bins.width_ps));
    }

    #[test]
    fn only_a_replay_takes_a_speed() {
        let mut r = request("mock");
        r.speed = 10.0;
        assert_eq!(
            r.job().unwrap_err().to_string(),
            "--speed plays a recording back faster (--device replay:FILE); mock runs at its own pace"
        );
        let mut r = request("replay:run.ptu");
        r.speed = 10.0;
        let (job, _) = r.job().unwrap();
        assert!(matches!(
            job.device,
            DeviceSpec::Replay(ReplaySpec { speed: 10.0, .. })
        ));
    }
}
