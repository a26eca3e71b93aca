//! Devices by name: `mock` (in-process USB), `mock-serial` (a real
//! pseudo-terminal), `serial:PATH`, `usb:VID:PID[:SERIAL]`,
//! `picoquant[:FAMILY][:SERIAL]`: parsing an address, listing what is
//! attached, and opening any of them as an acquisition [`Source`].

use std::str::FromStr;

pub use scatterscope_drivers::discovery::DeviceEntry;
use scatterscope_drivers::discovery::{serial_ports, usb_devices};
use scatterscope_drivers::usb::UsbSelector;

use ndarray::Array2;

use super::mock::MockSpec;
use super::open_error::OpenError;
use super::picoquant::{PicoQuantDevice, PicoQuantSource};
use super::source::Source;
use crate::physics::Setup;

/// A device address as given to `--device`, with what the device needs
/// beyond its address (a mock's scene and behaviour, a PicoQuant device's
/// settings).
#[derive(Debug, Clone)]
pub enum DeviceSpec {
    /// The mock time tagger on an in-process USB transport.
    Mock(MockSpec),
    /// The mock time tagger behind a pseudo-terminal, opened as a serial port.
    MockSerial(MockSpec),
    /// A serial port (USB-CDC time tagger).
    Serial(String),
    /// A USB time tagger.
    Usb(UsbSelector),
    /// A PicoQuant time tagger through the vendor's library.
    PicoQuant(PicoQuantDevice),
    /// A recording played back at its recorded pace.
    Replay(super::replay::ReplaySpec),
}

impl FromStr for DeviceSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mock" => Ok(Self::Mock(MockSpec::default())),
            "mock-serial" => Ok(Self::MockSerial(MockSpec::default())),
            _ => {
                if let Some(path) = s.strip_prefix("serial:") {
                    if path.is_empty() {
                        return Err("`serial:` needs a port path, e.g. serial:/dev/ttyACM0".into());
                    }
                    Ok(Self::Serial(path.to_string()))
                } else if let Some(rest) = s.strip_prefix("picoquant") {
                    match rest {
                        "" => Ok(Self::PicoQuant(Default::default())),
                        _ => match rest.strip_prefix(':') {
                            Some(r) => super::picoquant::PicoQuantSpec::parse(r).map(|spec| {
                                Self::PicoQuant(PicoQuantDevice {
                                    spec,
                                    ..Default::default()
                                })
                            }),
                            None => Err(format!(
                                "unknown device `{s}`: did you mean picoquant:{rest}?"
                            )),
                        },
                    }
                } else if let Some(path) = s.strip_prefix("replay:") {
                    if path.is_empty() {
                        return Err("`replay:` needs a recording, e.g. replay:run.ptu".into());
                    }
                    Ok(Self::Replay(super::replay::ReplaySpec {
                        path: path.into(),
                        speed: 1.0,
                    }))
                } else if let Some(rest) = s.strip_prefix("usb:") {
                    rest.parse().map(Self::Usb)
                } else {
                    Err(format!(
                        "unknown device `{s}`: use mock, mock-serial, serial:PATH, usb:VID:PID[:SERIAL], picoquant[:FAMILY][:SERIAL] or replay:FILE (see `scatterscope devices`)"
                    ))
                }
            }
        }
    }
}

impl std::fmt::Display for DeviceSpec {
    /// The address as `--device` takes it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Mock(_) => write!(f, "mock"),
            Self::MockSerial(_) => write!(f, "mock-serial"),
            Self::Serial(p) => write!(f, "serial:{p}"),
            Self::Usb(sel) => write!(f, "{sel}"),
            Self::PicoQuant(spec) => write!(f, "{spec}"),
            Self::Replay(r) => write!(f, "replay:{}", r.path.display()),
        }
    }
}

impl DeviceSpec {
    /// The scene a mock images, as its sensor sees it under `setup` (the
    /// truth a reconstruction is judged against); `None` for hardware.
    pub fn known_scene(&self, setup: &Setup) -> Option<Array2<f64>> {
        match self {
            Self::Mock(mock) | Self::MockSerial(mock) => super::mock::scene_truth(mock, setup),
            _ => None,
        }
    }

    /// Whether the device is a sensor array of the wire protocol (our own
    /// devices, the mocks, a tag file played back), whose stack takes the
    /// sample's physics and window; else a vendor's point detector or
    /// scanner (a PicoQuant device, a PTU played back), binned over its
    /// sync period unless a window is given.
    pub fn is_sensor(&self) -> bool {
        match self {
            Self::PicoQuant(_) => false,
            Self::Replay(r) => crate::formats::detect::is_tag_file(&r.path),
            _ => true,
        }
    }

    /// Whether this names a mock device.
    pub fn is_mock(&self) -> bool {
        matches!(self, Self::Mock(_) | Self::MockSerial(_))
    }
}

/// What `devices` finds.
#[derive(Debug, Clone, Default)]
pub struct DeviceList {
    /// Every address, hardware first, then the two mocks.
    pub all: Vec<DeviceEntry>,
    /// How many of them are hardware.
    pub hardware: usize,
    /// Vendor libraries that did not load, and why (where it looked).
    pub notes: Vec<String>,
}

/// Every device `acquire --device` can open here: USB time taggers with
/// known ids, serial ports, PicoQuant devices the vendor's libraries (or
/// `picoquant_library`) find, then the two mocks. Listing never fails.
pub fn list_devices(picoquant_library: Option<&std::path::Path>) -> DeviceList {
    let mut all = usb_devices();
    all.extend(serial_ports());
    let (picoquant, notes) = super::picoquant::list_picoquant(picoquant_library);
    all.extend(
        picoquant
            .into_iter()
            .map(|(address, description)| DeviceEntry {
                address,
                description,
            }),
    );
    let hardware = all.len();
    all.push(DeviceEntry {
        address: "mock".into(),
        description: "emulated time tagger on an in-process USB transport".into(),
    });
    all.push(DeviceEntry {
        address: "mock-serial".into(),
        description: "emulated time tagger behind a pseudo-terminal".into(),
    });
    DeviceList {
        all,
        hardware,
        notes,
    }
}

impl DeviceList {
    /// Whether no PicoQuant vendor library loaded (each family's note
    /// says where it looked).
    pub fn no_picoquant_library(&self) -> bool {
        self.notes.len() == scatterscope_drivers::picoquant::Family::ALL.len()
    }

    /// As a table: how many are hardware, one line per address, then the
    /// libraries that did not load.
    pub fn table(&self) -> Vec<String> {
        std::iter::once(format!("{} hardware device(s)", self.hardware))
            .chain(
                self.all
                    .iter()
                    .map(|d| format!("  {:<28} {}", d.address, d.description)),
            )
            .chain(self.notes.iter().map(|n| format!("note: {n}")))
            .collect()
    }
}

/// An opened device.
pub struct OpenedDevice {
    /// The device as an acquisition source.
    pub source: Box<dyn Source>,
    /// For a mock, its scene as the sensor sees it (the truth).
    pub truth: Option<Array2<f64>>,
}

/// Opens `spec` as an acquisition source; a mock is built from `setup`
/// (its sensor, medium and window), which hardware does not need.
pub fn open_device(spec: &DeviceSpec, setup: Option<&Setup>) -> Result<OpenedDevice, OpenError> {
    let link = |link: scatterscope_drivers::Link| OpenedDevice {
        source: Box::new(super::link::LinkSource::new(link)),
        truth: None,
    };
    match spec {
        DeviceSpec::Mock(mock) | DeviceSpec::MockSerial(mock) => {
            let setup = setup.ok_or_else(|| {
                OpenError::Usage("a mock device needs the sample's physics (a set-up)".into())
            })?;
            let serial = matches!(spec, DeviceSpec::MockSerial(_));
            let (source, truth) = super::mock::open_spec(mock, serial, setup)?;
            Ok(OpenedDevice {
                source,
                truth: Some(truth),
            })
        }
        DeviceSpec::Serial(path) => Ok(link(scatterscope_drivers::serial::open(
            path,
            scatterscope_drivers::serial::DEFAULT_BAUD,
        )?)),
        DeviceSpec::PicoQuant(device) => {
            device.check_settings().map_err(OpenError::Setting)?;
            Ok(OpenedDevice {
                source: Box::new(PicoQuantSource::open(device)?),
                truth: None,
            })
        }
        DeviceSpec::Replay(r) => Ok(OpenedDevice {
            source: Box::new(
                super::replay::FileSource::open(&r.path, r.speed).map_err(OpenError::Replay)?,
            ),
            truth: None,
        }),
        DeviceSpec::Usb(sel) => {
            #[cfg(feature = "rusb")]
            if std::env::var_os("SCATTERSCOPE_USB_BACKEND").is_some_and(|v| v == "rusb") {
                return Ok(link(scatterscope_drivers::usb::open_rusb(sel)?));
            }
            Ok(link(scatterscope_drivers::usb::open_nusb(sel)?))
        }
    }
}
