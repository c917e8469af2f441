//! The emulated board, transport-free: the firmware's own logic ([`control::board`]: command
//! handler, modes, limits, faults, commissioning; the upload handler and `control::slots`'
//! two-slot storage) on emulated hardware ([`super::hw`]: the motor emulator behind a
//! six-step bridge, Hall inputs and a current sense, wired in any order).
//!
//! Feed received bytes to [`EmulatedBoard::receive`], call [`EmulatedBoard::tick`] every control
//! period, send what [`EmulatedBoard::take_output`] returns.
use super::emulated_flash::RamFlash;
use super::hw::{Hardware, Wiring};
use crate::emulator::EmulatorConfig;
use anyhow::{anyhow, Result};
use control::blob::{self, Coefficients};
use control::board::{handle_upload, store_coefficients, Board};
use control::frame::{
    self, BoardMsg, FrameDecoder, HostMsg, Mode, Upload, Warning, MAX_ENCODED_LEN,
};
use control::slots::Slots;

/// Nominal bus voltage of the emulated board [V]: a 6S LiPo at rest (the firmware's
/// `V_BUS_NOMINAL`, 22.2 V).
pub const V_BUS_NOMINAL: f32 = 22.2;

/// The emulated board: [`control::board::Board`] (the firmware's logic) on emulated
/// hardware, with the serial transport and the flash of `control`.
pub struct EmulatedBoard {
    hw: Hardware,
    board: Board,
    slots: Slots<RamFlash>,
    upload: Upload,
    decoder: FrameDecoder,
    out: Vec<u8>,
}

/// Frames `msg` into `out`.
fn put(out: &mut Vec<u8>, msg: BoardMsg) {
    let mut buf = [0u8; MAX_ENCODED_LEN];
    if let Ok(f) = frame::encode_frame(&msg, &mut buf) {
        out.extend_from_slice(f);
    }
}

impl EmulatedBoard {
    /// A board at power-up: loads the newest valid coefficient slot of `flash` (or runs
    /// without compensation, with a warning, as the firmware does); the motor is connected
    /// as `wiring` says.
    pub fn new(plant: EmulatorConfig, wiring: Wiring, flash: RamFlash) -> Result<EmulatedBoard> {
        let mut slots = flash.into_slots()?;
        let loaded = slots
            .load()
            .map_err(|e| anyhow!("emulated flash read: {e:?}"))?;
        let loaded = loaded.map(|(info, c)| (c, info.seq));
        let none = loaded.is_none();
        // "emu-" marks the emulated board; the version is the firmware crate's.
        let mut board = Board::new(
            loaded,
            concat!("emu-", env!("CARGO_PKG_VERSION")),
            V_BUS_NOMINAL,
        );
        // The emulated stop arms at once; the board learns it as from the firmware's boot.
        board.set_hardware_stop(true, false);
        let mut emu = EmulatedBoard {
            hw: Hardware::new(plant, wiring)?,
            board,
            slots,
            upload: Upload::new(),
            decoder: FrameDecoder::new(),
            out: Vec::new(),
        };
        if none {
            put(&mut emu.out, BoardMsg::Warning(Warning::NoCoefficients));
        }
        Ok(emu)
    }

    /// The loaded coefficients.
    pub fn coefficients(&self) -> &Coefficients {
        self.board.coefficients()
    }

    /// Sequence number of the loaded slot (0: none).
    pub fn coeff_seq(&self) -> u32 {
        self.board.coeff_seq()
    }

    /// True while a run (speed, experiment, commissioning) is active.
    pub fn is_running(&self) -> bool {
        self.board.mode() != Mode::Idle
    }

    /// The board logic.
    pub fn board(&self) -> &Board {
        &self.board
    }

    /// The emulated hardware (motor truth).
    pub fn hardware(&self) -> &Hardware {
        &self.hw
    }

    /// Emulates the boot self-test of the hardware over-current stop: `armed` false is a
    /// stop that failed to arm (it never trips, and the board is told so, as the firmware
    /// does); `run_without` is the firmware's `run-without-hw-stop` build.
    pub fn set_hardware_stop(&mut self, armed: bool, run_without: bool) {
        self.hw.set_stop_armed(armed);
        self.board.set_hardware_stop(armed, run_without);
        if !armed {
            put(&mut self.out, BoardMsg::Warning(Warning::NoHardwareStop));
        }
    }

    /// The emulated hardware, to change what it measures (e.g. the bus voltage).
    pub fn hardware_mut(&mut self) -> &mut Hardware {
        &mut self.hw
    }

    /// Bytes to send to the host (whole frames).
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// Bytes received from the host.
    pub fn receive(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.decoder.push::<HostMsg>(b) {
                None => {}
                Some(Err(_)) => put(&mut self.out, BoardMsg::Warning(Warning::BadFrame)),
                Some(Ok(msg)) => self.handle(&msg),
            }
        }
    }

    /// One host message, as the firmware's link task and control loop handle it.
    pub fn handle(&mut self, msg: &HostMsg) {
        let out = &mut self.out;
        let faulted = self.board.fault().is_some();
        if self.board.handle(msg, &mut |m| put(out, m)) {
            if faulted && self.board.fault().is_none() {
                self.hw.rearm();
            }
            return;
        }
        let idle = self.board.mode() == Mode::Idle;
        if let Some((reply, new)) = handle_upload(msg, &mut self.upload, &mut self.slots, idle) {
            if let Some((c, seq)) = new {
                self.board.load(c, seq);
            }
            put(&mut self.out, reply);
        }
    }

    /// One 12 ms control period: measure, run the board logic, drive the motor. The loop
    /// period the telemetry reports is the nominal one (see [`EmulatedBoard::tick_timed`]).
    pub fn tick(&mut self) {
        self.tick_timed(control::CONTROL_PERIOD_S * 1.0e6);
    }

    /// [`EmulatedBoard::tick`] with the time since the previous period started [µs] of board
    /// time, for the telemetry's loop period and jitter (`motorid board` measures it on the
    /// host's clock). The emulated board has no cycle counter: its `step_cycles_max` is 0;
    /// and it never overruns: a late host thread stretches a period (jitter), the step still
    /// runs whole.
    pub fn tick_timed(&mut self, period_us: f32) {
        let mut m = self.hw.measure();
        m.period_us = period_us;
        let out = &mut self.out;
        let drive = self.board.tick(&m, &mut |msg| put(out, msg));
        store_coefficients(&mut self.board, &mut self.slots, &mut |msg| put(out, msg));
        self.hw.apply(drive, f64::from(control::CONTROL_PERIOD_S));
    }
}

/// Blob helper for tests and tools: decode or say why not.
pub fn decode_blob(bytes: &[u8]) -> Result<Coefficients> {
    blob::decode(bytes).map_err(|e| anyhow!("{e}"))
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;
    use control::commission::{CommissionError, CommissionOutcome};
    use control::frame::{decode_frame, encode_frame, Excitation, Fault, Nack, Sample, CHUNK_LEN};

    fn frame(msg: &HostMsg) -> Vec<u8> {
        let mut buf = [0u8; MAX_ENCODED_LEN];
        encode_frame(msg, &mut buf).unwrap().to_vec()
    }

    fn replies(emu: &mut EmulatedBoard) -> Vec<BoardMsg> {
        emu.take_output()
            .split_inclusive(|&b| b == 0)
            .map(|f| decode_frame::<BoardMsg>(f).unwrap())
            .collect()
    }

    fn chunk(index: u16, bytes: &[u8]) -> HostMsg {
        let mut m = HostMsg::UploadChunk {
            index,
            data: Default::default(),
        };
        if let HostMsg::UploadChunk { data, .. } = &mut m {
            data.extend_from_slice(bytes).unwrap();
        }
        m
    }

    /// Sends `blob` through the upload handler (begin, each chunk `sends` times, commit).
    fn send_blob(emu: &mut EmulatedBoard, blob: &[u8], sends: usize) {
        emu.receive(&frame(&HostMsg::UploadBegin {
            total_len: blob.len() as u16,
            crc: control::blob::CRC32.checksum(blob),
        }));
        for (k, c) in blob.chunks(CHUNK_LEN).enumerate() {
            for _ in 0..sends {
                emu.receive(&frame(&chunk(k as u16, c)));
            }
        }
        emu.receive(&frame(&HostMsg::UploadCommit));
    }

    /// The largest `|f(sample)|` of a run.
    fn peak(samples: &[Sample], f: impl Fn(&Sample) -> f32) -> f32 {
        samples.iter().map(|s| f(s).abs()).fold(0.0, f32::max)
    }

    /// The paper motor with its rotor locked (an enormous viscous load).
    fn locked_rotor() -> EmulatorConfig {
        let mut plant = EmulatorConfig::paper();
        plant.extra_load = Some(std::sync::Arc::new(|x| 1.0e4 * x.omega));
        plant
    }

    /// A board on the paper motor whose flash holds nothing, its boot output unread.
    fn empty_board() -> EmulatedBoard {
        EmulatedBoard::new(
            EmulatorConfig::paper(),
            Wiring::default(),
            RamFlash::new(None),
        )
        .unwrap()
    }

    #[test]
    fn upload_with_a_retried_chunk_commits_once_and_is_refused_while_running() {
        let mut emu = empty_board();
        assert_eq!(
            replies(&mut emu),
            [BoardMsg::Warning(Warning::NoCoefficients)]
        );
        let co = Coefficients {
            model: control::blob::ModelKind::Lugre,
            lugre: Some(control::lugre::LugreParams::paper()),
            ..identified()
        };
        let blob = crate::board::coeffs::encode(&co).unwrap();
        // Each ack lost: the host sends every chunk again.
        send_blob(&mut emu, &blob, 2);
        let r = replies(&mut emu);
        assert_eq!(r.last(), Some(&BoardMsg::Committed { seq: 1 }));
        assert!(!r.iter().any(|m| matches!(m, BoardMsg::Nack(_))), "{r:?}");
        assert_eq!(emu.coefficients(), &co);
        // A replayed commit finds no upload.
        emu.receive(&frame(&HostMsg::UploadCommit));
        assert_eq!(replies(&mut emu), [BoardMsg::Nack(Nack::NoUpload)]);
        // Running: samples flow, commits are refused.
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        emu.tick();
        emu.tick();
        let r = replies(&mut emu);
        assert_eq!(r[0], BoardMsg::Ack);
        assert!(
            matches!(r[2], BoardMsg::Sample(Sample { seq: 1, .. })),
            "{r:?}"
        );
        send_blob(&mut emu, &blob, 0);
        let r = replies(&mut emu);
        assert_eq!(r.last(), Some(&BoardMsg::Nack(Nack::Busy)));
    }

    /// Upload `co` through the board's own upload handler.
    fn upload(emu: &mut EmulatedBoard, co: &Coefficients) {
        send_blob(emu, &crate::board::coeffs::encode(co).unwrap(), 1);
        let r = replies(emu);
        assert!(
            matches!(r.last(), Some(BoardMsg::Committed { .. })),
            "{r:?}"
        );
    }

    /// Ticks until a fault (returned with the samples seen) or `n` periods.
    fn run_until_fault(emu: &mut EmulatedBoard, n: usize) -> (Option<Fault>, Vec<Sample>) {
        let mut samples = Vec::new();
        for k in 0..n {
            if k.is_multiple_of(50) {
                // As a listening host does: a sign of life now and then.
                emu.receive(&frame(&HostMsg::Heartbeat));
            }
            emu.tick();
            for m in replies(emu) {
                match m {
                    BoardMsg::Sample(s) => samples.push(s),
                    BoardMsg::Fault(f) => return (Some(f), samples),
                    _ => {}
                }
            }
        }
        (None, samples)
    }

    /// R·i_max [V] of the default coefficients.
    fn co_default_r_i_max() -> f32 {
        let co = identified();
        co.motor.r * co.limits.i_max
    }

    /// The default coefficients, marked as identified (speed mode needs it).
    fn identified() -> Coefficients {
        Coefficients {
            motor_identified: true,
            ..Coefficients::default()
        }
    }

    fn board_with(plant: EmulatorConfig, co: Option<&Coefficients>) -> EmulatedBoard {
        let mut emu = EmulatedBoard::new(plant, Wiring::default(), RamFlash::new(None)).unwrap();
        replies(&mut emu);
        if let Some(co) = co {
            upload(&mut emu, co);
        }
        emu
    }

    #[test]
    fn speed_and_experiment_need_a_valid_blob_and_sane_parameters() {
        let mut emu = board_with(EmulatorConfig::paper(), None);
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::A,
            duration_s: 1.0,
        }));
        assert_eq!(
            replies(&mut emu),
            [
                BoardMsg::Nack(Nack::NoCoefficients),
                BoardMsg::Nack(Nack::NoCoefficients)
            ]
        );
        assert!(!emu.is_running());
        // A damaged upload is refused and changes nothing.
        let blob = crate::board::coeffs::encode(&identified()).unwrap();
        let mut bad = blob.clone();
        bad[20] ^= 0x40;
        send_blob(&mut emu, &bad, 1);
        assert_eq!(
            replies(&mut emu).last(),
            Some(&BoardMsg::Nack(Nack::BadBlob))
        );
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        assert_eq!(replies(&mut emu), [BoardMsg::Nack(Nack::NoCoefficients)]);
        // Identify and commissioning stay allowed.
        emu.receive(&frame(&HostMsg::Identify));
        assert!(matches!(
            replies(&mut emu)[0],
            BoardMsg::Identity { coeff_seq: 0, .. }
        ));
        emu.receive(&frame(&HostMsg::Commission));
        assert_eq!(replies(&mut emu), [BoardMsg::Ack]);
        emu.receive(&frame(&HostMsg::Stop));
        replies(&mut emu);

        upload(&mut emu, &identified());
        for (signal, duration_s) in [
            (Excitation::A, f32::NAN),
            (Excitation::A, f32::INFINITY),
            (Excitation::A, 1.0e9),
            (Excitation::A, -1.0),
            (Excitation::A, 0.0),
            (Excitation::Steady { volts: 100.0 }, 1.0),
            (Excitation::Steady { volts: f32::NAN }, 1.0),
        ] {
            emu.receive(&frame(&HostMsg::StartExperiment { signal, duration_s }));
            assert_eq!(
                replies(&mut emu),
                [BoardMsg::Nack(Nack::OutOfRange)],
                "{signal:?} {duration_s}"
            );
        }
        // Amplitudes are relative to u_max and R·i_max, the smaller: signal d steps up to
        // 5/12·12 V = 5 V by the default u_max, 0.35·0.216 Ω·30 A = 2.27 V by the current.
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::D,
            duration_s: 6.0,
        }));
        let (f, samples) = run_until_fault(&mut emu, 600);
        assert_eq!(f, None);
        assert_eq!(samples.len(), 500);
        let peak = peak(&samples, |s| s.u);
        let by_current = 0.35 * co_default_r_i_max();
        // Above 1 V: the signal was played (its size is 2.27 V); 1e-4 V: f32 rounding of the window.
        assert!(peak > 1.0 && peak <= by_current + 1e-4, "peak {peak}");
    }

    #[test]
    fn u_max_from_the_blob_bounds_the_speed_loop() {
        let mut co = identified();
        co.pi.u_max = 3.0;
        let mut emu = board_with(EmulatorConfig::paper(), Some(&co));
        // The speed limit is the no-load speed at u_max (42 rad/s): friction keeps the motor
        // below it, and the loop at its voltage limit.
        let top = emu.board().speed_limit();
        // 1e-3 rad/s: f32 rounding of 42 rad/s (an ulp is 4e-6).
        assert!((top - 3.0 / co.motor.kb).abs() < 1e-3, "{top}");
        emu.receive(&frame(&HostMsg::SetSpeed { omega_ref: top }));
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        let (f, samples) = run_until_fault(&mut emu, 150);
        assert_eq!(f, None);
        let peak = peak(&samples, |s| s.u);
        // 1e-6 V: the f32 u_max of 3 V (an ulp is 2.4e-7).
        assert!((peak - 3.0).abs() < 1e-6, "peak {peak}");
    }

    #[test]
    fn overcurrent_trips_and_turns_the_bridge_off() {
        // A blob whose R is five times the motor's: both current windows are five times
        // too wide, and the measured current's gain of 0.5 over-corrects (g·ρ = 2.5): the
        // current passes the trip in the first period.
        let mut co = identified();
        co.limits.i_max = 5.0;
        co.motor.r *= 5.0;
        let mut emu = board_with(EmulatorConfig::paper(), Some(&co));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 6.0 },
            duration_s: 2.0,
        }));
        replies(&mut emu);
        let (f, _) = run_until_fault(&mut emu, 50);
        assert_eq!(f, Some(Fault::OverCurrent));
        assert!(!emu.is_running());
        // Latched: no start until cleared.
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        assert_eq!(replies(&mut emu), [BoardMsg::Nack(Nack::Faulted)]);
        // The bridge is off: the current dies away.
        for _ in 0..20 {
            emu.tick();
        }
        assert!(emu.hardware().plant().truth().i.abs() < 1e-3);
        emu.receive(&frame(&HostMsg::ClearFault));
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        assert_eq!(replies(&mut emu), [BoardMsg::Ack, BoardMsg::Ack]);
    }

    #[test]
    fn a_locked_rotor_is_held_at_the_current_limit_then_stops_as_a_stall() {
        // A locked rotor and a voltage ramp of 8 V/s: 44 A after 1.2 s without a limit.
        let plant = locked_rotor();
        let mut co = identified();
        co.pi.u_max = 20.0;
        co.limits.i_max = 20.0;
        let mut emu = board_with(plant, Some(&co));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::Ramp { volts_per_s: 8.0 },
            duration_s: 3.0,
        }));
        replies(&mut emu);
        let (f, samples) = run_until_fault(&mut emu, 300);
        assert_eq!(f, Some(Fault::Stall));
        // Held at 0.8·i_max = 16 A, below the 20 A trip, for the stall time.
        let peak = peak(&samples, |s| s.i);
        assert!(peak <= 16.5, "peak {peak} A");
        let last = samples.last().map_or(0.0, |s| s.i);
        assert!((last - 16.0).abs() < 1.0, "last {last} A");
        let held = samples.iter().filter(|s| s.i > 15.5).count() as u32;
        let n = control::board::STALL_PERIODS;
        assert!(
            (n - 3..=n + 1).contains(&held),
            "{held} periods at the limit"
        );
    }

    #[test]
    fn the_hardware_stop_cuts_a_short_until_the_fault_is_cleared() {
        // A locked rotor and 12 V on 0.22 Ω: 55 A within a few milliseconds of the first
        // period, before the 12 ms software limit (the widest allowed) can act. The blob
        // says R is ten times the winding's, so the current window lets 12 V through (as a
        // shorted winding would).
        let plant = locked_rotor();
        let mut co = identified();
        co.limits.i_max = control::board::HW_TRIP_A;
        co.motor.r *= 10.0;
        let mut emu = board_with(plant, Some(&co));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 12.0 },
            duration_s: 2.0,
        }));
        replies(&mut emu);
        let (f, samples) = run_until_fault(&mut emu, 10);
        assert_eq!(f, Some(Fault::HardwareOverCurrent));
        assert!(samples.len() <= 1, "{} samples", samples.len());
        assert!(!emu.is_running());
        // Cut within the period: by its end the winding current has died away.
        let i = emu.hardware().plant().truth().i.abs();
        assert!(i < 1.0, "{i} A after the stop");
        // Held off until cleared: a start is refused, ClearFault re-arms.
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        assert_eq!(replies(&mut emu), [BoardMsg::Nack(Nack::Faulted)]);
        emu.receive(&frame(&HostMsg::ClearFault));
        emu.tick();
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        assert_eq!(replies(&mut emu), [BoardMsg::Ack, BoardMsg::Ack]);
    }

    #[test]
    fn a_blocked_rotor_is_a_stall_fault() {
        let plant = locked_rotor();
        let mut co = identified();
        co.limits.i_max = control::board::HW_TRIP_A;
        let mut emu = board_with(plant, Some(&co));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 8.0 },
            duration_s: 10.0,
        }));
        replies(&mut emu);
        let (f, samples) = run_until_fault(&mut emu, 200);
        assert_eq!(f, Some(Fault::Stall));
        let n = samples.len() as u32;
        assert!(
            (control::board::STALL_PERIODS - 2..=control::board::STALL_PERIODS + 2).contains(&n),
            "{n} samples"
        );
        assert!(!emu.is_running());
    }

    #[test]
    fn an_ecc_error_in_the_newest_slot_boots_on_the_other() {
        // Two uploads (slot 0, then slot 1), then a double ECC error in slot 1's header, as
        // a commit cut by a power loss leaves it: the board boots on slot 0 instead of
        // hanging, and the next upload rewrites slot 1.
        let mut slots = RamFlash::new(None).into_slots().unwrap();
        let old = identified();
        let mut new = identified();
        new.pi.kp = 0.125;
        slots
            .store(&crate::board::coeffs::encode(&old).unwrap())
            .unwrap();
        slots
            .store(&crate::board::coeffs::encode(&new).unwrap())
            .unwrap();
        let mut flash = slots.into_inner();
        flash.inject_ecc_error(super::super::emulated_flash::PAGE + 8);
        let mut emu =
            EmulatedBoard::new(EmulatorConfig::paper(), Wiring::default(), flash).unwrap();
        assert_eq!(replies(&mut emu), []);
        assert_eq!((emu.coeff_seq(), emu.coefficients()), (1, &old));
        // Speed mode is allowed: the board has valid coefficients.
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        emu.receive(&frame(&HostMsg::Stop));
        assert_eq!(replies(&mut emu), [BoardMsg::Ack, BoardMsg::Ack]);
        // The unreadable slot's sequence number is lost: the rewrite outranks slot 0.
        upload(&mut emu, &new);
        assert_eq!((emu.coeff_seq(), emu.coefficients()), (2, &new));
    }

    #[test]
    fn a_corrupted_blob_in_flash_boots_without_coefficients_and_refuses_runs() {
        // One valid slot, then a bit of its blob flipped in the flash file (a cell that lost
        // its charge, not an ECC error): the slot's CRC fails, the board boots without
        // coefficients, warns, and allows identify and commissioning only.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flash.bin");
        let mut slots = RamFlash::new(Some(path.clone())).into_slots().unwrap();
        slots
            .store(&crate::board::coeffs::encode(&identified()).unwrap())
            .unwrap();
        drop(slots);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[control::slots::SLOT_HEADER_LEN + 30] ^= 0x01;
        std::fs::write(&path, &bytes).unwrap();

        let mut emu = EmulatedBoard::new(
            EmulatorConfig::paper(),
            Wiring::default(),
            RamFlash::new(Some(path)),
        )
        .unwrap();
        assert_eq!(
            replies(&mut emu),
            [BoardMsg::Warning(Warning::NoCoefficients)]
        );
        assert_eq!(emu.coeff_seq(), 0);
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        emu.receive(&frame(&HostMsg::StartExperiment {
            signal: Excitation::C,
            duration_s: 1.0,
        }));
        emu.receive(&frame(&HostMsg::Identify));
        emu.receive(&frame(&HostMsg::Commission));
        let r = replies(&mut emu);
        assert_eq!(r[0], BoardMsg::Nack(Nack::NoCoefficients));
        assert_eq!(r[1], BoardMsg::Nack(Nack::NoCoefficients));
        assert!(
            matches!(r[2], BoardMsg::Identity { coeff_seq: 0, .. }),
            "{r:?}"
        );
        assert_eq!(r[3], BoardMsg::Ack);
        assert!(emu.is_running());
    }

    #[test]
    fn silence_on_the_link_stops_a_run_and_heartbeats_keep_it() {
        let mut emu = board_with(EmulatorConfig::paper(), Some(&identified()));
        emu.receive(&frame(&HostMsg::SetSpeed { omega_ref: 20.0 }));
        emu.receive(&frame(&HostMsg::SetMode { mode: Mode::Speed }));
        replies(&mut emu);
        for k in 0..400u32 {
            if k.is_multiple_of(50) {
                emu.receive(&frame(&HostMsg::Heartbeat));
            }
            emu.tick();
        }
        assert!(emu.is_running());
        let mut lost = None;
        for k in 0..400 {
            emu.tick();
            if replies(&mut emu).contains(&BoardMsg::Warning(Warning::LinkLost)) {
                lost = Some(k);
                break;
            }
        }
        let k = lost.expect("no link-loss stop");
        assert!(k as u32 <= control::board::LINK_TIMEOUT_PERIODS, "{k}");
        assert!(!emu.is_running());
    }

    /// Ticks until the commissioning ends; its outcome.
    fn commission_result(emu: &mut EmulatedBoard, extra: &[(usize, HostMsg)]) -> CommissionOutcome {
        commission_run(emu, extra).0
    }

    /// Ticks until the commissioning ends; its outcome and the periods it took.
    fn commission_run(
        emu: &mut EmulatedBoard,
        extra: &[(usize, HostMsg)],
    ) -> (CommissionOutcome, usize) {
        for k in 0..2000 {
            for (_, m) in extra.iter().filter(|(at, _)| *at == k) {
                emu.receive(&frame(m));
            }
            emu.tick();
            for m in replies(emu) {
                if let BoardMsg::Commission { outcome, .. } = m {
                    if !matches!(
                        outcome,
                        CommissionOutcome::Running
                            | CommissionOutcome::Failed(CommissionError::Aborted)
                    ) {
                        return (outcome, k + 1);
                    }
                }
            }
        }
        panic!("no commissioning result")
    }

    /// A board wired with the Hall connector 231 and the phases 321, commissioning.
    fn commissioning_board() -> EmulatedBoard {
        let wiring = Wiring {
            hall_order: [1, 2, 0],
            phase_order: [2, 1, 0],
            current_inverted: false,
        };
        let mut emu =
            EmulatedBoard::new(EmulatorConfig::paper(), wiring, RamFlash::new(None)).unwrap();
        replies(&mut emu);
        emu.receive(&frame(&HostMsg::Commission));
        assert_eq!(replies(&mut emu), [BoardMsg::Ack]);
        emu
    }

    /// Periods into a run of `periods` in all: in the first hold (the ramp's), in the counted
    /// revolution (holds 3 to 5), in the backward pass (holds 6 to 8). The ramp extends the
    /// first hold only, so the later holds are the run's last ones.
    fn restart_periods(periods: usize) -> [usize; 3] {
        use control::commission::{HOLDS, HOLD_PERIODS};
        let h = usize::from(HOLD_PERIODS);
        let counted = periods - (usize::from(HOLDS) - 3) * h;
        let backward = periods - (usize::from(HOLDS) - 6) * h;
        let first_ends = periods - (usize::from(HOLDS) - 1) * h;
        assert!(
            first_ends > h,
            "the ramp held the first vector {first_ends} periods"
        );
        [h / 4, counted + h / 2, backward + h / 2]
    }

    #[test]
    fn a_retried_commission_request_leaves_the_run_as_it_was() {
        // The host resends `Commission` when the Ack comes late: in the middle of a hold,
        // of the counted revolution, of the backward pass.
        let (once, periods) = commission_run(&mut commissioning_board(), &[]);
        assert!(matches!(once, CommissionOutcome::Done(_)), "{once:?}");
        for at in restart_periods(periods) {
            let mut emu = commissioning_board();
            let again = commission_result(&mut emu, &[(at, HostMsg::Commission)]);
            assert_eq!(again, once, "Commission again after {at} periods");
        }
    }

    #[test]
    fn commissioning_started_on_a_turning_rotor_learns_the_same_table() {
        // A run stopped mid-way and started again at once: the rotor is still turning and
        // the winding still carries the stopped run's current.
        let (CommissionOutcome::Done(once), periods) =
            commission_run(&mut commissioning_board(), &[])
        else {
            panic!("the first run failed");
        };
        for at in restart_periods(periods) {
            let mut emu = commissioning_board();
            let again =
                commission_result(&mut emu, &[(at, HostMsg::Stop), (at, HostMsg::Commission)]);
            let CommissionOutcome::Done(c) = again else {
                panic!("restarted after {at} periods: {again:?}");
            };
            assert_eq!(c.sequence, once.sequence, "restarted after {at} periods");
            assert_eq!(c.edges_per_elec_rev, 6);
        }
    }

    /// The three wirings the start scan covers: the commissioning board's, the default,
    /// and one whose phase order reverses the motor.
    const SCAN_WIRINGS: [([u8; 3], [u8; 3]); 3] = [
        ([1, 2, 0], [2, 1, 0]),
        ([0, 1, 2], [0, 1, 2]),
        ([0, 2, 1], [2, 0, 1]),
    ];

    /// A fresh board wired `(hall, phase)` commissioned after `idle` periods at rest with
    /// the rotor at `theta` [rad]; its outcome.
    fn commission_from(wiring: ([u8; 3], [u8; 3]), idle: usize, theta: f64) -> CommissionOutcome {
        let wiring = Wiring {
            hall_order: wiring.0,
            phase_order: wiring.1,
            current_inverted: false,
        };
        let mut emu =
            EmulatedBoard::new(EmulatorConfig::paper(), wiring, RamFlash::new(None)).unwrap();
        emu.hardware_mut().place_rotor(theta);
        replies(&mut emu);
        for _ in 0..idle {
            emu.tick();
        }
        replies(&mut emu);
        emu.receive(&frame(&HostMsg::Commission));
        commission_result(&mut emu, &[])
    }

    /// What a board wired `wiring` should learn: sector k is the motor's sector the board's
    /// centre k points at.
    fn wanted_sequence(wiring: Wiring) -> [u8; 6] {
        std::array::from_fn(|k| {
            let motor = wiring.aligned_sector(k as u8);
            wiring.hall(control::commission::DEFAULT_SEQUENCE[usize::from(motor)])
        })
    }

    /// A fresh board wired `wiring`, its Hall sensors `offset` [° electrical] off the
    /// six-step positions with `hysteresis` [°], commissioned from rotor angle `theta` [rad].
    fn commission_with_halls(
        wiring: Wiring,
        theta: f64,
        (offset, hysteresis): (f64, f64),
    ) -> CommissionOutcome {
        let mut emu =
            EmulatedBoard::new(EmulatorConfig::paper(), wiring, RamFlash::new(None)).unwrap();
        emu.hardware_mut().place_rotor(theta);
        emu.hardware_mut().set_hall_placement(offset, hysteresis);
        replies(&mut emu);
        emu.receive(&frame(&HostMsg::Commission));
        commission_result(&mut emu, &[])
    }

    /// Hysteresis of the emulated Hall sensors [° electrical]: ±5° around each boundary, a
    /// generous figure for a latching Hall sensor's switching band on a multi-pole magnet.
    const HALL_HYSTERESIS_DEG: f64 = 10.0;

    #[test]
    fn misplaced_halls_end_in_the_right_table_or_an_error_never_a_wrong_table() {
        // Sensors 30° off put the held rotor on a boundary again, and 15-20° off often
        // within the band friction leaves it in (the more so as the ramp's first holds drive
        // little current): the backward pass comes to every centre from the other side, and
        // the hysteresis makes it read the other state.
        let step: f64 = control::hall::step_angle(EmulatorConfig::paper().pole_pairs);
        for offset in [-30.0, -20.0, -15.0, 15.0, 20.0, 30.0] {
            for w in SCAN_WIRINGS {
                let wiring = Wiring {
                    hall_order: w.0,
                    phase_order: w.1,
                    current_inverted: false,
                };
                for theta in [0.0, 1.25 * step, 3.5 * step] {
                    let r = commission_with_halls(wiring, theta, (offset, HALL_HYSTERESIS_DEG));
                    // Below 30° a run may still read right; a wrong table is never stored.
                    let ok = match r {
                        CommissionOutcome::Failed(_) => true,
                        CommissionOutcome::Done(c) => {
                            offset.abs() < 30.0 && c.sequence == wanted_sequence(wiring)
                        }
                        _ => false,
                    };
                    assert!(ok, "{offset}°, {w:?} from {theta}: {r:?}");
                }
            }
        }
    }

    #[test]
    fn commissioning_succeeds_whenever_it_starts() {
        // The rotor rests until `Commission` arrives: the idle periods change only the
        // current sense's noise the run sees. Then rotor angles over one electrical
        // revolution, boundaries and a sector's middle among them.
        let step: f64 = control::hall::step_angle(EmulatorConfig::paper().pole_pairs);
        let starts = (0..300usize)
            .map(|idle| (idle, 0.0))
            .chain((0..12).map(|k| (0, (0.5 * f64::from(k) + 0.25) * step)))
            .chain([(0, 0.5 * step), (0, 3.5 * step), (0, 3.0 * step)]);
        let mut bad = Vec::new();
        for (idle, theta) in starts {
            for w in SCAN_WIRINGS {
                let r = commission_from(w, idle, theta);
                let wiring = Wiring {
                    hall_order: w.0,
                    phase_order: w.1,
                    current_inverted: false,
                };
                let want = wanted_sequence(wiring);
                if !matches!(r, CommissionOutcome::Done(c)
                    if c.edges_per_elec_rev == 6 && c.sequence == want)
                {
                    bad.push((idle, theta, w, r));
                }
            }
        }
        assert!(bad.is_empty(), "{} failed: {bad:?}", bad.len());
    }

    /// Mean torque per amp [N·m/A] in the direction the decoded angle counts up (sector
    /// numbers of `learned`), of a motor wired as `wiring` driven six-step at `volts` through
    /// `table`: the back-EMF `applied − R·I` over the speed, averaged once it has settled.
    fn forward_torque_per_amp(
        wiring: Wiring,
        table: control::hall::HallTable,
        learned: control::hall::HallTable,
        volts: f32,
    ) -> f64 {
        let cfg = EmulatorConfig::paper();
        let (kt, kb, r) = (cfg.motor.kt, cfg.motor.kb, cfg.motor.r);
        let mut hw = Hardware::new(cfg, wiring).unwrap();
        let drive = control::board::Drive::SixStep { volts, table };
        let dt = f64::from(control::CONTROL_PERIOD_S);
        // One second to settle, then one to average.
        let n = (1.0 / dt).round() as usize;
        for _ in 0..n {
            hw.apply(drive, dt);
        }
        hw.measure();
        let (mut emf, mut w, mut sectors) = (0.0, 0.0, 0i64);
        let mut last = learned.sector_of(hw.measure().hall);
        for _ in 0..n {
            hw.apply(drive, dt);
            let t = hw.plant().truth();
            emf += t.applied_voltage - r * (1.0 + t.heat) * t.i;
            w += t.omega;
            for e in hw.measure().edges {
                let s = learned.sector_of(e.state);
                if let (Some(a), Some(b)) = (last, s) {
                    sectors += match (i64::from(b) - i64::from(a)).rem_euclid(6) {
                        1 => 1,
                        5 => -1,
                        _ => 0,
                    };
                }
                last = s;
            }
        }
        // The quotient needs the rotor turning: a mean speed of a hundredth of the no-load
        // speed at `volts` (a stalled rotation would give NaN or a huge quotient, which the
        // ranking would take for the best).
        let w_mean = w / n as f64;
        let w_no_load = f64::from(volts) / kb;
        assert!(
            w_mean.abs() >= 0.01 * w_no_load,
            "the rotor stalled under this table (mean speed {w_mean} rad/s against the \
             no-load {w_no_load} rad/s): no torque per amp"
        );
        // The board's forward direction in the motor's: the sign of the sector count per
        // turn of the rotor.
        let forward = if (sectors as f64) * w > 0.0 {
            1.0
        } else {
            -1.0
        };
        forward * kt / kb * emf / w
    }

    #[test]
    fn the_learned_table_gives_the_most_torque_per_amp_of_its_rotations() {
        // A table off by a sector still turns the motor, with the torque angle 30° off
        // its centre: less torque per amp under the trapezoidal back-EMF.
        for w in SCAN_WIRINGS {
            let CommissionOutcome::Done(c) = commission_from(w, 0, 0.0) else {
                panic!("{w:?}: commissioning failed");
            };
            let wiring = Wiring {
                hall_order: w.0,
                phase_order: w.1,
                current_inverted: false,
            };
            let learned = c.hall_table().unwrap();
            let volts = 6.0;
            let tpa: Vec<f64> = (0..6)
                .map(|rot| {
                    let seq = std::array::from_fn(|k| c.sequence[(k + 6 - rot) % 6]);
                    let table = control::hall::HallTable::from_sequence(seq).unwrap();
                    forward_torque_per_amp(wiring, table, learned, volts)
                })
                .collect();
            let best = (0..6).max_by(|&a, &b| tpa[a].total_cmp(&tpa[b])).unwrap();
            assert_eq!(best, 0, "{w:?}: torque per amp by rotation {tpa:?}");
        }
    }
}
