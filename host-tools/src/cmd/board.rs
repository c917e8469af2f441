//! `motorid board`: the emulated board behind a pseudo-terminal.
use crate::board::emulated_board::EmulatedBoard;
use crate::board::emulated_flash::RamFlash;
use crate::board::hw::{parse_order, Wiring};
use crate::board::pace::{HostView, Pacer};
use crate::board::pty::Pty;
use crate::effect_spec::EffectSpec;
use crate::emulator::EmulatorConfig;
use anyhow::{bail, Context, Result};
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// Run the emulated board: the firmware's control step and serial protocol (from the
/// `control` crate) driving the built-in motor emulator, reachable through a pseudo-terminal
/// as if it were the B-G431B-ESC1's serial port.
///
/// Prints the device path (e.g. /dev/pts/3) on the first line of standard output; point
/// `motorid upload --port` and `motorid record --port` at it. Runs until interrupted.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serve on a new pseudo-terminal (the only transport for now).
    #[arg(long)]
    pub pty: bool,
    /// Time factor: 1 = real time (one 12 ms step every 12 ms), 10 = ten times faster.
    /// While the host leaves the board's output unread, the board runs at real time, so a
    /// paused host loses the link after the board's 2 s timeout at any factor.
    #[arg(long, value_parser = crate::validate::parse_speed, allow_hyphen_values = true, default_value_t = 1.0)]
    pub speed: f64,
    /// Add a physical effect to the emulated motor (`NAME` or `NAME:key=value,...`, as in
    /// `motorid simulate --effect`).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Seed of the sensor noise and of the excitation signals.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Keep the emulated coefficient flash in this file (survives restarts).
    #[arg(long, value_name = "FILE")]
    pub flash: Option<PathBuf>,
    /// Hall connector wiring: board inputs H1 H2 H3 carry the motor's sensors in this order
    /// (a permutation of 1, 2, 3; `motorid commission` learns it).
    #[arg(long, value_name = "ORDER", default_value = "123")]
    pub hall_order: String,
    /// Phase connector wiring: bridge outputs U V W drive the motor's phases in this order
    /// (a permutation of 1, 2, 3; 132 reverses the direction).
    #[arg(long, value_name = "ORDER", default_value = "123")]
    pub phase_order: String,
    /// The current sense is wired with the opposite sign.
    #[arg(long)]
    pub invert_current: bool,
}

pub fn run(args: Args) -> Result<()> {
    if !args.pty {
        bail!("choose how the emulated board is reached: --pty (a pseudo-terminal)");
    }
    if !(args.speed.is_finite() && args.speed > 0.0) {
        bail!(
            "--speed: must be a positive number (got {})",
            crate::validate::show(args.speed)
        );
    }
    let mut plant = EmulatorConfig::paper();
    plant.seed = args.seed;
    for spec in &args.effects {
        let s: EffectSpec = EffectSpec::parse_flag("--effect", spec)?;
        plant.effects.push(s.to_effect());
    }
    let wiring = Wiring {
        hall_order: parse_order(&args.hall_order).context("--hall-order")?,
        phase_order: parse_order(&args.phase_order).context("--phase-order")?,
        current_inverted: args.invert_current,
    };
    // An existing flash file must be a flash image: a regular file of at most the flash's size.
    if let Some(f) = args.flash.as_ref().filter(|f| f.exists()) {
        crate::input::read(f, crate::board::emulated_flash::SIZE as u64, "flash image")?;
    }
    let mut emu = EmulatedBoard::new(plant, wiring, RamFlash::new(args.flash.clone()))?;
    let pty = Pty::open()?;
    println!("{}", pty.path.display());
    std::io::stdout().flush()?;
    eprintln!(
        "emulated board on {} (time ×{}, coefficients: {}); stop with Ctrl-C",
        crate::log::echo_path(&pty.path),
        args.speed,
        if emu.coeff_seq() == 0 {
            "none".to_string()
        } else {
            format!("slot sequence {}", emu.coeff_seq())
        }
    );

    // Reader: bytes from the host. Writer: bytes to the host; when nobody reads and the
    // terminal's buffer is full, output is dropped, as a UART with nobody listening would.
    let mut master_r = pty.master.try_clone().context("cannot duplicate the pty")?;
    let mut master_w = pty.master.try_clone().context("cannot duplicate the pty")?;
    let (in_tx, in_rx) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        while let Ok(n) = master_r.read(&mut buf) {
            if n == 0 || in_tx.send(buf[..n].to_vec()).is_err() {
                break;
            }
        }
    });
    let (out_tx, out_rx) = mpsc::sync_channel::<Vec<u8>>(4096);
    // Bytes handed to the writer and not yet written to the terminal.
    let queued = Arc::new(AtomicUsize::new(0));
    let written = Arc::clone(&queued);
    std::thread::spawn(move || {
        while let Ok(bytes) = out_rx.recv() {
            let ok = write_through(&mut master_w, &bytes);
            written.fetch_sub(bytes.len(), Ordering::Relaxed);
            if !ok {
                break;
            }
        }
    });
    let out = Output { tx: out_tx, queued };

    // Board time is the count of periods run; the host's clock only says when the next one
    // is due (see `crate::board::pace`).
    let mut pacer = Pacer::new(args.speed, Instant::now());
    // Periods since the last byte from the host.
    let mut quiet = 0u32;
    loop {
        // What the host sent so far is handled before the period, as the firmware's link
        // task hands it to the control loop.
        loop {
            match in_rx.try_recv() {
                Ok(bytes) => {
                    emu.receive(&bytes);
                    quiet = 0;
                }
                Err(mpsc::TryRecvError::Empty) => break,
                Err(mpsc::TryRecvError::Disconnected) => bail!("the pseudo-terminal closed"),
            }
        }
        out.flush(&mut emu);
        let host = HostView::of(&emu, out.unread(&pty), quiet);
        let wait = pacer.wait(Instant::now(), host);
        if wait.is_zero() {
            let period_us = pacer.ran(Instant::now(), host);
            emu.tick_timed(period_us);
            quiet = quiet.saturating_add(1);
            out.flush(&mut emu);
            continue;
        }
        // Wait for host bytes until the period is due; a host that is behind is looked at
        // again every millisecond (it may read meanwhile).
        let wait = if host.behind() {
            wait.min(Duration::from_millis(1))
        } else {
            wait
        };
        match in_rx.recv_timeout(wait) {
            Ok(bytes) => {
                emu.receive(&bytes);
                quiet = 0;
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the pseudo-terminal closed"),
        }
        out.flush(&mut emu);
    }
}

/// The board's output on its way to the host.
struct Output {
    tx: mpsc::SyncSender<Vec<u8>>,
    /// Bytes handed to the writer thread, not yet written to the terminal.
    queued: Arc<AtomicUsize>,
}

impl Output {
    /// Hands the board's output to the writer (dropped when the writer is far behind).
    fn flush(&self, emu: &mut EmulatedBoard) {
        let bytes = emu.take_output();
        let n = bytes.len();
        if n > 0 {
            self.queued.fetch_add(n, Ordering::Relaxed);
            if self.tx.try_send(bytes).is_err() {
                self.queued.fetch_sub(n, Ordering::Relaxed);
            }
        }
    }

    /// Bytes of output the host has not read yet: queued for the terminal or in it.
    fn unread(&self, pty: &Pty) -> usize {
        self.queued.load(Ordering::Relaxed) + pty.unread()
    }
}

/// Writes `bytes` to the terminal, waiting while its buffer is full; false when the terminal
/// is gone.
fn write_through(w: &mut impl Write, mut bytes: &[u8]) -> bool {
    while !bytes.is_empty() {
        match w.write(bytes) {
            Ok(0) => std::thread::sleep(Duration::from_millis(1)),
            Ok(n) => bytes = &bytes[n..],
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::Interrupted | std::io::ErrorKind::WouldBlock
                ) =>
            {
                std::thread::sleep(Duration::from_millis(1))
            }
            Err(_) => return false,
        }
    }
    true
}
