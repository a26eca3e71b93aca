//! Devices by name: `mock` (in-process USB), `mock-serial` (a real
//! pseudo-terminal), `serial:PATH`, `usb:VID:PID[:SERIAL]`: parsing an
//! address, listing what is attached, and opening it (mocks included).

use std::str::FromStr;

pub use scatterscope_drivers::discovery::DeviceEntry;
use scatterscope_drivers::discovery::{serial_ports, usb_devices};
use scatterscope_drivers::usb::UsbSelector;
use scatterscope_drivers::{Link, LinkError};

pub use super::mock::{MockHandle, MockSetup};

/// A device address as given to `--device`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSpec {
    /// The mock time tagger on an in-process USB transport.
    Mock,
    /// The mock time tagger behind a pseudo-terminal, opened as a serial port.
    MockSerial,
    /// A serial port (USB-CDC time tagger).
    Serial(String),
    /// A USB time tagger.
    Usb(UsbSelector),
    /// A PicoQuant time tagger through the vendor's library.
    PicoQuant(super::picoquant::PicoQuantSpec),
}

impl FromStr for DeviceSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mock" => Ok(Self::Mock),
            "mock-serial" => Ok(Self::MockSerial),
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
                            Some(r) => {
                                super::picoquant::PicoQuantSpec::parse(r).map(Self::PicoQuant)
                            }
                            None => Err(format!(
                                "unknown device `{s}`: did you mean picoquant:{rest}?"
                            )),
                        },
                    }
                } else if let Some(rest) = s.strip_prefix("usb:") {
                    rest.parse().map(Self::Usb)
                } else {
                    Err(format!(
                        "unknown device `{s}`: use mock, mock-serial, serial:PATH, usb:VID:PID[:SERIAL] or picoquant[:FAMILY][:SERIAL] (see `scatterscope devices`)"
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
            Self::Mock => write!(f, "mock"),
            Self::MockSerial => write!(f, "mock-serial"),
            Self::Serial(p) => write!(f, "serial:{p}"),
            Self::Usb(sel) => write!(f, "{sel}"),
            Self::PicoQuant(spec) => write!(f, "{spec}"),
        }
    }
}

impl DeviceSpec {
    /// Whether this names a mock device.
    pub fn is_mock(&self) -> bool {
        matches!(self, Self::Mock | Self::MockSerial)
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
        address: DeviceSpec::Mock.to_string(),
        description: "emulated time tagger on an in-process USB transport".into(),
    });
    all.push(DeviceEntry {
        address: DeviceSpec::MockSerial.to_string(),
        description: "emulated time tagger behind a pseudo-terminal".into(),
    });
    DeviceList {
        all,
        hardware,
        notes,
    }
}

impl DeviceList {
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

/// An opened link, and the mock behind it if any.
pub struct OpenedDevice {
    /// The transport.
    pub link: Link,
    /// The emulated device (its true counts), for mocks.
    pub mock: Option<MockHandle>,
}

/// Why a device cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// Transport failure.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The mock's scene or physics is unusable.
    #[error("the mock's scene or physics: {0}")]
    Mock(String),
    /// A mock was asked for without its set-up, or in a build without mocks.
    #[error("{0}")]
    Usage(String),
    /// The pseudo-terminal could not be created.
    #[error("creating the mock's pseudo-terminal: {0}")]
    Pty(std::io::Error),
}

/// Opens `spec`; mocks are started from `mock` (required for them).
pub fn open_device(spec: &DeviceSpec, mock: Option<MockSetup>) -> Result<OpenedDevice, OpenError> {
    match spec {
        DeviceSpec::Mock | DeviceSpec::MockSerial => {
            let setup = mock.ok_or_else(|| {
                OpenError::Usage("a mock device needs a scene and physics".into())
            })?;
            let (link, handle) = super::mock::open(spec, setup)?;
            Ok(OpenedDevice {
                link,
                mock: Some(handle),
            })
        }
        DeviceSpec::Serial(path) => Ok(OpenedDevice {
            link: scatterscope_drivers::serial::open(
                path,
                scatterscope_drivers::serial::DEFAULT_BAUD,
            )?,
            mock: None,
        }),
        DeviceSpec::PicoQuant(_) => Err(OpenError::Usage(
            "a PicoQuant device is not opened as a protocol link: run it as an acquire::picoquant::PicoQuantJob".into(),
        )),
        DeviceSpec::Usb(sel) => {
            #[cfg(feature = "rusb")]
            if std::env::var_os("SCATTERSCOPE_USB_BACKEND").is_some_and(|v| v == "rusb") {
                return Ok(OpenedDevice {
                    link: scatterscope_drivers::usb::open_rusb(sel)?,
                    mock: None,
                });
            }
            Ok(OpenedDevice {
                link: scatterscope_drivers::usb::open_nusb(sel)?,
                mock: None,
            })
        }
    }
}
