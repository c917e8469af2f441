//! A pseudo-terminal for the board emulator: the emulator holds the master side, a client
//! opens the slave device (`/dev/pts/N`) like any serial port.
use anyhow::{Context, Result};
use rustix::fd::OwnedFd;
use rustix::pty::{grantpt, openpt, ptsname, unlockpt, OpenptFlags};
use rustix::termios::{tcgetattr, tcsetattr, OptionalActions};
use std::fs::File;
use std::path::PathBuf;

/// An open pseudo-terminal.
pub struct Pty {
    /// The master side: what the emulated board reads and writes.
    pub master: File,
    /// The slave device path, for clients.
    pub path: PathBuf,
    /// The emulator keeps the slave open itself, so that clients may come and go without
    /// the master seeing a hang-up.
    slave: OwnedFd,
}

impl Pty {
    /// Bytes the emulator wrote that no client has read yet (the slave's input queue).
    pub fn unread(&self) -> usize {
        rustix::io::ioctl_fionread(&self.slave).map_or(0, |n| n as usize)
    }

    /// Open a pseudo-terminal in raw mode (no echo, no line editing, all 256 byte values).
    pub fn open() -> Result<Pty> {
        let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY)
            .context("cannot open a pseudo-terminal (posix_openpt)")?;
        grantpt(&master).context("grantpt failed")?;
        unlockpt(&master).context("unlockpt failed")?;
        let name = ptsname(&master, Vec::new()).context("ptsname failed")?;
        let path = PathBuf::from(name.to_string_lossy().into_owned());
        let slave: OwnedFd = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .with_context(|| format!("cannot open {}", crate::log::echo_path(&path)))?
            .into();
        let mut t = tcgetattr(&slave).context("tcgetattr failed")?;
        t.make_raw();
        tcsetattr(&slave, OptionalActions::Now, &t).context("tcsetattr failed")?;
        Ok(Pty {
            master: File::from(master),
            path,
            slave,
        })
    }
}
