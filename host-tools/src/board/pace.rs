//! When the emulated board runs its next control period, on the host's clock.
//!
//! The board's logic counts time in control periods: each [`super::emulated_board::EmulatedBoard::tick`]
//! is one 12 ms period of board time, whatever the host's clock did meanwhile. At time
//! factor `s` a period is due every 12/s ms of host time; a board thread that was late runs
//! the periods it missed one after the other (at most [`MAX_CATCH_UP`] of them, then it
//! drops the rest of the delay), so board time never jumps and no step is merged.
//!
//! A host that falls behind (its process paused, the machine overloaded, the kernel late
//! to move the terminal's bytes) must not see more board time pass than the real board lets
//! pass: while more than [`HOST_BACKLOG`] bytes of the board's output wait unread, or a run
//! that stops on link loss has heard nothing from the host for [`HOST_QUIET`] periods,
//! periods are due every 12 ms of host time (real time). The board's link timeout
//! ([`control::board::LINK_TIMEOUT_PERIODS`], 2 s) is then 2 s of host time at any time
//! factor, and a host that keeps up sees the same run at any factor.
use super::emulated_board::EmulatedBoard;
use control::frame::Mode;
use std::time::{Duration, Instant};

/// Unread output [bytes] beyond which the host counts as not reading: some 15 samples,
/// 0.2 s of board time, against the 2 s link timeout.
pub const HOST_BACKLOG: usize = 512;
/// Periods without a byte from the host, in a run that stops on link loss, beyond which the
/// host counts as behind: 0.3 s of board time; a listening host sends a frame every 0.12 s.
pub const HOST_QUIET: u32 = 25;
/// Missed periods a late board thread runs to catch up before it drops the rest of its
/// delay.
pub const MAX_CATCH_UP: u32 = 10;

/// What the emulator sees of the host when a period is due.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HostView {
    /// Bytes of the board's output the host has not read yet, as far as the emulator sees
    /// (bytes the kernel has not moved yet are not seen).
    pub unread: usize,
    /// Periods run since the last byte from the host.
    pub quiet: u32,
    /// A run that stops on link loss (speed, experiment) is going.
    pub watched: bool,
}

impl HostView {
    /// The host beside `emu` with `unread` bytes of output not read and `quiet` periods
    /// since its last byte.
    pub fn of(emu: &EmulatedBoard, unread: usize, quiet: u32) -> HostView {
        HostView {
            unread,
            quiet,
            watched: matches!(emu.board().mode(), Mode::Speed | Mode::Experiment),
        }
    }

    /// The host is behind the board: periods go at real time.
    pub fn behind(&self) -> bool {
        self.unread > HOST_BACKLOG || (self.watched && self.quiet > HOST_QUIET)
    }
}

/// The schedule of the board's periods on the host's clock.
#[derive(Debug, Clone)]
pub struct Pacer {
    /// Host time per period at the time factor.
    fast: Duration,
    /// Host time per period at real time.
    real: Duration,
    speed: f64,
    /// When the next period is due at the time factor.
    next: Instant,
    /// When the last period ran.
    last: Option<Instant>,
}

impl Pacer {
    /// Periods at time factor `speed` (positive, finite; 1 = real time), the first due one
    /// period after `now`.
    pub fn new(speed: f64, now: Instant) -> Pacer {
        let real = Duration::from_secs_f64(f64::from(control::CONTROL_PERIOD_S));
        let fast = real.div_f64(speed);
        Pacer {
            fast,
            real,
            speed,
            next: now + fast,
            last: None,
        }
    }

    /// Host time from `now` until the next period is due, the host as `host` (zero: due
    /// now).
    pub fn wait(&self, now: Instant, host: HostView) -> Duration {
        let mut due = self.next;
        if host.behind() {
            if let Some(last) = self.last {
                due = due.max(last + self.real.max(self.fast));
            }
        }
        due.saturating_duration_since(now)
    }

    /// A period runs at `now`, the host as `host`: schedules the next and returns the time
    /// since the previous period [µs] of board time (NaN for the first), for the board's
    /// loop telemetry.
    pub fn ran(&mut self, now: Instant, host: HostView) -> f32 {
        let factor = if host.behind() {
            self.speed.min(1.0)
        } else {
            self.speed
        };
        let period_us = self.last.map_or(f32::NAN, |t| {
            ((now - t).as_secs_f64() * factor * 1.0e6) as f32
        });
        self.last = Some(now);
        self.next += self.fast;
        if self.next + self.fast * MAX_CATCH_UP < now {
            self.next = now + self.fast;
        }
        period_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::emulated_flash::RamFlash;
    use crate::board::hw::Wiring;
    use crate::emulator::EmulatorConfig;
    use control::commission::CommissionOutcome;
    use control::frame::{
        decode_frame, encode_frame, BoardMsg, Excitation, HostMsg, Sample, Warning, MAX_ENCODED_LEN,
    };

    fn frame(msg: &HostMsg) -> Vec<u8> {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        encode_frame(msg, &mut buf).unwrap().to_vec()
    }

    /// A host on a schedule of host time [s] → awake: when awake it reads all the board's
    /// output and, as `motorid record` does, sends a heartbeat every 10 samples read.
    struct Host<F: Fn(f64) -> bool> {
        awake: F,
        unread: Vec<u8>,
        /// Frames sent, not yet taken in by the board.
        sent: Vec<u8>,
        samples: Vec<Sample>,
        commission: Option<CommissionOutcome>,
        link_lost: bool,
    }

    impl<F: Fn(f64) -> bool> Host<F> {
        fn new(awake: F) -> Self {
            Host {
                awake,
                unread: Vec::new(),
                sent: Vec::new(),
                samples: Vec::new(),
                commission: None,
                link_lost: false,
            }
        }

        /// At host time `t`: read if awake.
        fn act(&mut self, t: f64) {
            if (self.awake)(t) {
                self.read();
            }
        }

        /// Read all the board's output, answer as `record` does.
        fn read(&mut self) {
            for f in std::mem::take(&mut self.unread).split_inclusive(|&b| b == 0) {
                match decode_frame::<BoardMsg>(f) {
                    Ok(BoardMsg::Sample(s)) => {
                        self.samples.push(s);
                        if self.samples.len().is_multiple_of(10) {
                            self.sent.extend(frame(&HostMsg::Heartbeat));
                        }
                    }
                    Ok(BoardMsg::Commission { outcome, .. })
                        if outcome != CommissionOutcome::Running =>
                    {
                        self.commission = Some(outcome)
                    }
                    Ok(BoardMsg::Warning(Warning::LinkLost)) => self.link_lost = true,
                    _ => {}
                }
            }
        }
    }

    /// `motorid board`'s loop in simulated host time: the board (at time factor `speed`,
    /// its thread awake when `board_awake(t)`) paced by [`Pacer`], the host beside it;
    /// `start` is sent before the first period; runs until `periods` periods have run.
    /// `backlog_seen` false: the emulator never sees the unread output (the kernel holds it).
    fn play<F: Fn(f64) -> bool>(
        speed: f64,
        backlog_seen: bool,
        board_awake: impl Fn(f64) -> bool,
        host: &mut Host<F>,
        wiring: Wiring,
        start: &[HostMsg],
        periods: usize,
    ) {
        let mut emu =
            EmulatedBoard::new(EmulatorConfig::paper(), wiring, RamFlash::new(None)).unwrap();
        for m in start {
            emu.receive(&frame(m));
        }
        host.unread.extend(emu.take_output());
        let t0 = Instant::now();
        let mut pacer = Pacer::new(speed, t0);
        // Host time advances in steps of 50 µs.
        let dt = Duration::from_micros(50);
        let (mut now, mut ran, mut quiet) = (t0, 0, 0);
        while ran < periods {
            let t = (now - t0).as_secs_f64();
            host.act(t);
            if board_awake(t) {
                if !host.sent.is_empty() {
                    emu.receive(&std::mem::take(&mut host.sent));
                    quiet = 0;
                }
                let view = |emu: &EmulatedBoard, host: &Host<F>, quiet| {
                    let unread = if backlog_seen { host.unread.len() } else { 0 };
                    HostView::of(emu, unread, quiet)
                };
                while pacer.wait(now, view(&emu, host, quiet)).is_zero() {
                    let us = pacer.ran(now, view(&emu, host, quiet));
                    emu.tick_timed(us);
                    host.unread.extend(emu.take_output());
                    ran += 1;
                    quiet += 1;
                }
            }
            now += dt;
        }
    }

    fn upload_default(start: &mut Vec<HostMsg>) {
        let co = control::blob::Coefficients {
            motor_identified: true,
            ..Default::default()
        };
        let blob = crate::board::coeffs::encode(&co).unwrap();
        start.push(HostMsg::UploadBegin {
            total_len: blob.len() as u16,
            crc: control::blob::CRC32.checksum(&blob),
        });
        for (k, c) in blob.chunks(control::frame::CHUNK_LEN).enumerate() {
            let mut chunk = HostMsg::UploadChunk {
                index: k as u16,
                data: Default::default(),
            };
            if let HostMsg::UploadChunk { data, .. } = &mut chunk {
                data.extend_from_slice(c).unwrap();
            }
            start.push(chunk);
        }
        start.push(HostMsg::UploadCommit);
    }

    #[test]
    fn a_host_that_pauses_sees_the_same_run_at_fifty_times_real_time() {
        // A 10 s experiment (834 samples) at 50x; the host pauses for 60 ms of every 100 ms:
        // 250 periods at 50x, beyond the 167-period link timeout, were the board to run on.
        let mut start = Vec::new();
        upload_default(&mut start);
        start.push(HostMsg::StartExperiment {
            signal: Excitation::A,
            duration_s: 10.0,
        });
        let mut steady = Host::new(|_| true);
        play(
            50.0,
            true,
            |_| true,
            &mut steady,
            Wiring::default(),
            &start,
            900,
        );
        assert!(!steady.link_lost, "link lost");
        assert_eq!(steady.samples.len(), 834);
        // The emulator sees the output pile up, or it does not (the kernel holds it): then
        // the host's silence in the run tells.
        for backlog_seen in [true, false] {
            let mut pausing = Host::new(|t: f64| (t * 1.0e3).rem_euclid(100.0) < 40.0);
            let (w, s) = (Wiring::default(), &start);
            play(50.0, backlog_seen, |_| true, &mut pausing, w, s, 900);
            // What the pausing host had not read yet when the board's periods ran out.
            pausing.read();
            assert!(
                !pausing.link_lost,
                "link lost, backlog seen: {backlog_seen}"
            );
            assert_eq!(
                pausing.samples, steady.samples,
                "backlog seen: {backlog_seen}"
            );
        }
    }

    #[test]
    fn commissioning_is_the_same_on_a_board_thread_that_stalls() {
        // Hall connector 231, phases 321 (as `motorid board --hall-order 231
        // --phase-order 321`); 50x real time. The board thread stalls 30 ms of every 70 ms
        // (more than the catch-up: board time is dropped, never jumped); the host reads
        // late, in bursts.
        let wiring = Wiring {
            hall_order: [1, 2, 0],
            phase_order: [2, 1, 0],
            current_inverted: false,
        };
        let start = [HostMsg::Commission];
        // The longest run.
        let periods = usize::from(control::commission::RUN_PERIODS_MAX) + 50;
        let mut regular = Host::new(|_| true);
        play(50.0, true, |_| true, &mut regular, wiring, &start, periods);
        let mut late = Host::new(|t: f64| (t * 1.0e3).rem_euclid(45.0) < 5.0);
        play(
            50.0,
            true,
            |t: f64| (t * 1.0e3).rem_euclid(70.0) < 40.0,
            &mut late,
            wiring,
            &start,
            periods,
        );
        late.read();
        let done = regular.commission.expect("no commissioning result");
        assert!(matches!(done, CommissionOutcome::Done(_)), "{done:?}");
        // Bit for bit: the table, the pole-pair count and the f32 voltage.
        assert_eq!(late.commission, Some(done));
    }
}
