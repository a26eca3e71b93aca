//! The device behind a real pseudo-terminal: the host opens the slave side
//! with `serialport`, exactly as it opens a USB-CDC time tagger.

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::path::PathBuf;
use std::time::Duration;

use nix::poll::{PollFd, PollFlags, PollTimeout, poll};

use crate::{DevicePort, PortClosed};

/// The device's end of a pseudo-terminal.
pub struct PtyDevicePort {
    master: File,
    /// Held until the host's first bytes arrive, so the pty exists until
    /// the host opens it; released then, so the host closing its side
    /// shows as a hang-up.
    slave: Option<OwnedFd>,
    buf: Vec<u8>,
}

/// Opens a pseudo-terminal; returns the device port and the slave path the
/// host opens.
pub fn open() -> std::io::Result<(PtyDevicePort, PathBuf)> {
    let pty = nix::pty::openpty(None, None).map_err(std::io::Error::from)?;
    let flags = nix::fcntl::fcntl(pty.master.as_fd(), nix::fcntl::FcntlArg::F_GETFL)
        .map_err(std::io::Error::from)?;
    let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
    nix::fcntl::fcntl(pty.master.as_fd(), nix::fcntl::FcntlArg::F_SETFL(flags))
        .map_err(std::io::Error::from)?;
    let path = nix::unistd::ttyname(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    // Raw mode now, so nothing the device writes before the host opens the
    // port is echoed or translated.
    let mut t = nix::sys::termios::tcgetattr(pty.slave.as_fd()).map_err(std::io::Error::from)?;
    nix::sys::termios::cfmakeraw(&mut t);
    nix::sys::termios::tcsetattr(pty.slave.as_fd(), nix::sys::termios::SetArg::TCSANOW, &t)
        .map_err(std::io::Error::from)?;
    Ok((
        PtyDevicePort {
            master: File::from(pty.master),
            slave: Some(pty.slave),
            buf: vec![0; 1 << 16],
        },
        path,
    ))
}

impl DevicePort for PtyDevicePort {
    fn recv(&mut self, timeout: Duration) -> Result<Option<Vec<u8>>, PortClosed> {
        let ms = timeout.as_millis().min(u128::from(u16::MAX)) as u16;
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, PollTimeout::from(ms)) {
            Ok(0) => return Ok(None),
            Ok(_) => {}
            Err(nix::errno::Errno::EINTR) => return Ok(None),
            Err(_) => return Err(PortClosed),
        }
        let revents = fds[0].revents().unwrap_or(PollFlags::empty());
        if !revents.contains(PollFlags::POLLIN) {
            if self.slave.is_none() {
                return Err(PortClosed);
            }
            // Hang-up before the host opened the port: wait for it.
            std::thread::sleep(timeout.max(Duration::from_millis(1)));
            return Ok(None);
        }
        match self.master.read(&mut self.buf) {
            Ok(0) => Ok(None),
            Ok(n) => {
                self.slave = None;
                Ok(Some(self.buf[..n].to_vec()))
            }
            Err(e) if e.kind() == ErrorKind::Interrupted || e.kind() == ErrorKind::WouldBlock => {
                Ok(None)
            }
            Err(_) => Err(PortClosed),
        }
    }

    fn send(&mut self, bytes: &[u8]) -> Result<bool, PortClosed> {
        // Waits while the host does not read (the pty buffer is full), like
        // a device whose USB-CDC endpoint is not polled; a hang-up ends it.
        let mut rest = bytes;
        while !rest.is_empty() {
            match self.master.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLOUT)];
                    let r = poll(&mut fds, PollTimeout::from(50u16));
                    let hup = fds[0]
                        .revents()
                        .is_some_and(|r| r.contains(PollFlags::POLLHUP));
                    if r.is_err() || (hup && self.slave.is_none()) {
                        return Err(PortClosed);
                    }
                }
                Err(_) => return Err(PortClosed),
            }
        }
        Ok(true)
    }
}
