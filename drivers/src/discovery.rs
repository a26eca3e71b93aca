//! Device discovery: serial ports and USB devices with known ids. A machine
//! with neither prints an empty list; listing never fails.

use serde::Serialize;

/// USB ids of time taggers that speak the scatterscope protocol.
pub const KNOWN_USB_IDS: &[(u16, u16, &str)] = &[
    // pid.codes test id, used by the reference firmware.
    (0x1209, 0x0001, "scatterscope reference time tagger"),
];

/// One device the host can open.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct DeviceEntry {
    /// What `--device` takes to open it.
    pub address: String,
    /// Human-readable description.
    pub description: String,
}

/// Serial ports (USB-CDC and others) the operating system reports.
pub fn serial_ports() -> Vec<DeviceEntry> {
    let Ok(ports) = serialport::available_ports() else {
        return Vec::new();
    };
    ports
        .into_iter()
        .map(|p| {
            let description = match &p.port_type {
                serialport::SerialPortType::UsbPort(u) => format!(
                    "USB serial {:04x}:{:04x} {} {}{}",
                    u.vid,
                    u.pid,
                    u.manufacturer.as_deref().unwrap_or(""),
                    u.product.as_deref().unwrap_or(""),
                    u.serial_number
                        .as_deref()
                        .map(|s| format!(" (serial {s})"))
                        .unwrap_or_default()
                ),
                serialport::SerialPortType::PciPort => "PCI serial port".into(),
                serialport::SerialPortType::BluetoothPort => "Bluetooth serial port".into(),
                serialport::SerialPortType::Unknown => "serial port".into(),
            };
            DeviceEntry {
                address: format!("serial:{}", p.port_name),
                description,
            }
        })
        .collect()
}

/// USB devices whose ids are in [`KNOWN_USB_IDS`]. Without USB access (a
/// container without /sys/bus/usb) the list is empty.
pub fn usb_devices() -> Vec<DeviceEntry> {
    use nusb::MaybeFuture;
    // nusb reports a missing /sys/bus/usb as an error: that means "none".
    let Ok(devices) = nusb::list_devices().wait() else {
        return Vec::new();
    };
    devices
        .filter_map(|d| {
            let (_, _, name) = KNOWN_USB_IDS
                .iter()
                .find(|(v, p, _)| *v == d.vendor_id() && *p == d.product_id())?;
            let serial = d
                .serial_number()
                .map(|s| format!(":{s}"))
                .unwrap_or_default();
            Some(DeviceEntry {
                address: format!("usb:{:04x}:{:04x}{serial}", d.vendor_id(), d.product_id()),
                description: (*name).to_string(),
            })
        })
        .collect()
}
