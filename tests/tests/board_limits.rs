//! The board's limits on the emulated board, through the firmware's own logic
//! (`control::board::Board` in `motorid::board::emulated_board::EmulatedBoard`): the standing current limit,
//! the speed ramp, the speed limit and the size of the experiment signals.
use control::blob::{Coefficients, ModelKind, DERATE_FRACTION};
use control::commission::{CommissionError, CommissionOutcome};
use control::effects::Effect;
use control::frame::{BoardMsg, Excitation, Fault, HostMsg, Mode};
use control::lugre::LugreParams;
use control::step::{Faults, MEASURED_CURRENT_GAIN};
use motorid::board::emulated_board::EmulatedBoard;
use motorid::board::emulated_flash::RamFlash;
use motorid::board::hw::Wiring;
use motorid::emulator::EmulatorConfig;

/// The paper's motor with its LuGre compensation, as `motorid export` writes it for the
/// emulated motor, with the voltage limit `u_max` [V] and the current trip `i_max` [A].
fn paper_coefficients(u_max: f32, i_max: f32) -> Coefficients {
    let mut co = Coefficients {
        model: ModelKind::Lugre,
        lugre: Some(LugreParams::paper()),
        motor_identified: true,
        ..Coefficients::default()
    };
    co.pi.u_max = u_max;
    co.limits.i_max = i_max;
    co
}

/// The emulated paper motor on a board whose flash holds `co`.
fn board_with(co: &Coefficients) -> EmulatedBoard {
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(co).unwrap())
        .unwrap();
    let emu = EmulatedBoard::new(
        EmulatorConfig::paper(),
        Wiring::default(),
        slots.into_inner(),
    );
    emu.unwrap()
}

/// What one period showed: the true peak current [A] within it, the true speed at its end
/// [rad/s], the step's flags and the commanded voltage [V].
#[derive(Debug, Clone, Copy)]
struct Period {
    peak_i: f64,
    end_i: f64,
    omega: f64,
    faults: Faults,
    u: f32,
}

/// Runs `n` periods with a heartbeat now and then; returns each period and the first fault.
fn run(emu: &mut EmulatedBoard, n: usize) -> (Vec<Period>, Option<Fault>) {
    let mut periods = Vec::new();
    let mut fault = None;
    for k in 0..n {
        if k % 50 == 0 {
            emu.handle(&HostMsg::Heartbeat);
        }
        emu.tick();
        let out = *emu.board().last_step_outputs();
        periods.push(Period {
            peak_i: emu.hardware().peak_current(),
            end_i: emu.hardware().plant().truth().i.abs(),
            omega: emu.hardware().plant().truth().omega,
            faults: out.faults,
            u: out.v_cmd,
        });
        fault = fault.or(emu.board().fault());
        let _ = emu.take_output();
    }
    (periods, fault)
}

/// Allowance [A] over the current limit: the voltage window sits around the back-EMF of the
/// velocity *estimate*, so a speed error of one estimator resolution (one Hall step over the
/// moving average's 0.12 s, 0.79 rad/s) moves the current by `K_b·0.79/R` = 0.26 A; twice
/// that covers a late Hall edge. The current's own L/R transient within a period (1.4 ms
/// here) does not add to it: with the voltage held, the current moves monotonically from
/// its value at the period's start towards the window's steady state.
fn margin(co: &Coefficients) -> f64 {
    let res = std::f64::consts::TAU / (6.0 * f64::from(co.pole_pairs)) / 0.12;
    2.0 * f64::from(co.motor.kb) * res / f64::from(co.motor.r)
}

fn i_limit(co: &Coefficients) -> f64 {
    f64::from(DERATE_FRACTION * co.limits.i_max)
}

fn peak_current(p: &[Period]) -> f64 {
    p.iter().map(|x| x.peak_i).fold(0.0, f64::max)
}

fn mean_speed(p: &[Period]) -> f64 {
    p.iter().map(|x| x.omega).sum::<f64>() / p.len() as f64
}

#[test]
fn a_step_from_standstill_holds_the_current_limit_and_reaches_the_speed() {
    // From rest on the 0.22 Ω winding: 5 V draw 23 A at standstill, the board's full 21 V
    // about 100 A. Speed control (the ramp and the window) and an open-loop 20 V step (the
    // window alone), with the default trip and a low one.
    for i_max in [30.0, 10.0] {
        let co = paper_coefficients(24.0, i_max);
        let lim = i_limit(&co);
        let mut emu = board_with(&co);
        emu.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
        emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
        let (p, fault) = run(&mut emu, 300);
        assert_eq!(fault, None, "speed, i_max {i_max}");
        let peak = peak_current(&p);
        assert!(
            peak <= lim + margin(&co),
            "speed, i_max {i_max}: peak {peak} A, limit {lim} A + {} A",
            margin(&co)
        );
        let w = mean_speed(&p[250..]);
        // 2 % of the reference, five resolutions of the 0.79 rad/s estimate the loop
        // regulates: a check that it arrived, not of its accuracy.
        assert!((w - 200.0).abs() < 4.0, "speed, i_max {i_max}: {w} rad/s");
        // The PI did not wind up while the window held it: no overshoot beyond the 4 rad/s
        // (five estimate resolutions) allowed above plus one.
        let top = p.iter().map(|x| x.omega).fold(0.0, f64::max);
        assert!(
            top < 205.0,
            "speed, i_max {i_max}: overshoot to {top} rad/s"
        );
        if i_max == 10.0 {
            // The ramp alone would ask 8 A of acceleration and friction: the limit acts
            // (the model's window, or the measured current's, which lets the current rise
            // by half its distance to the limit per period).
            assert!(
                peak > f64::from(MEASURED_CURRENT_GAIN) * lim,
                "speed, i_max {i_max}: peak {peak} A"
            );
            assert!(p.iter().any(|x| x.faults.contains(Faults::CURRENT_LIMIT)));
        }

        let mut emu = board_with(&co);
        emu.handle(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 20.0 },
            duration_s: 4.0,
        });
        let (p, fault) = run(&mut emu, 300);
        assert_eq!(fault, None, "20 V, i_max {i_max}");
        let peak = peak_current(&p);
        // The measured-current window lets the current rise by half its distance to the
        // limit each period ([`MEASURED_CURRENT_GAIN`]), and the rotor's back-EMF takes
        // much of it away within the period: the peak lies between that half and the limit.
        assert!(
            peak <= lim + margin(&co) && peak > f64::from(MEASURED_CURRENT_GAIN) * lim,
            "20 V, i_max {i_max}: peak {peak} A, limit {lim} A + {} A",
            margin(&co)
        );
        // Held at the limit while it speeds up, then free: near the no-load speed of 20 V.
        assert!(p[..5]
            .iter()
            .all(|x| x.faults.contains(Faults::CURRENT_LIMIT)));
        let w = mean_speed(&p[250..]);
        let no_load = 20.0 / f64::from(co.motor.kb);
        // 0.9: friction near the no-load speed (α0 + α2·ω ≈ 0.5 N·m) draws about 7 A, whose
        // R·I drop takes about 8 % off it.
        assert!(
            w > 0.9 * no_load && w < no_load,
            "20 V, i_max {i_max}: {w} rad/s"
        );
    }
}

#[test]
fn the_speed_reference_ramps_at_half_the_limit_torque_and_reverses_within_the_limit() {
    let co = paper_coefficients(24.0, 10.0);
    let accel = co.ramp_acceleration(DERATE_FRACTION * co.limits.i_max);
    let per_period = accel * control::CONTROL_PERIOD_S;
    // 0.5·K_t·8 A/J = 950 rad/s²: 11.4 rad/s per period; 1 rad/s² (0.1 %) for K_t written
    // here to four digits.
    assert!((accel - 0.5 * 0.07126 * 8.0 / 3e-4).abs() < 1.0, "{accel}");
    let mut emu = board_with(&co);
    emu.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    let mut refs = vec![0.0f32];
    let mut periods = Vec::new();
    for k in 0..600 {
        if k == 300 {
            emu.handle(&HostMsg::SetSpeed { omega_ref: -200.0 });
        }
        let (p, fault) = run(&mut emu, 1);
        assert_eq!(fault, None, "period {k}");
        periods.extend(p);
        refs.push(emu.board().speed_reference());
    }
    // 1e-5 relative: f32 rounding of a reference near 200 rad/s (one ulp is 1.5e-5 rad/s,
    // 1.3e-6 of a step).
    for (k, w) in refs.windows(2).enumerate() {
        assert!(
            (w[1] - w[0]).abs() <= per_period * (1.0 + 1e-5),
            "period {k}: {} -> {}",
            w[0],
            w[1]
        );
    }
    // Straight up at the ramp's rate, then held; the same down to -200 rad/s.
    let up = (200.0 / per_period).ceil() as usize;
    // f32: the board forms the step in its own order (one ulp at 11 rad/s is 1e-6 rad/s).
    assert!((refs[1] - per_period).abs() < 1e-4, "{}", refs[1]);
    assert!(
        refs[up - 1] < 200.0 && refs[up] == 200.0,
        "{:?}",
        &refs[..up + 1]
    );
    let down = 300 + (400.0 / per_period).ceil() as usize;
    assert!(refs[down - 1] > -200.0 && refs[down] == -200.0);
    // The motor follows (within 4 rad/s as in the step test above), and braking through the
    // reversal holds the current limit too.
    assert!((mean_speed(&periods[250..300]) - 200.0).abs() < 4.0);
    assert!((mean_speed(&periods[550..]) + 200.0).abs() < 4.0);
    let peak = peak_current(&periods);
    assert!(peak <= i_limit(&co) + margin(&co), "peak {peak} A");
}

#[test]
fn speed_references_beyond_the_speed_limit_are_refused() {
    let nack = |emu: &mut EmulatedBoard, w: f32| {
        emu.handle(&HostMsg::SetSpeed { omega_ref: w });
        let out = emu.take_output();
        let msgs: Vec<BoardMsg> = out
            .split_inclusive(|&b| b == 0)
            .map(|f| control::frame::decode_frame(f).unwrap())
            .collect();
        msgs
    };
    // u_max 12 V over K_b 0.0713 V·s/rad: 168 rad/s; 50 pole pairs: the Hall capture's
    // 3920 edges/s are 82 rad/s.
    for (u_max, pole_pairs, want) in [(12.0, 11, 12.0 / 0.07126), (24.0, 50, 82.1)] {
        let mut co = paper_coefficients(u_max, 30.0);
        co.pole_pairs = pole_pairs;
        let mut emu = board_with(&co);
        let _ = emu.take_output();
        let limit = emu.board().speed_limit();
        // 0.1 rad/s: `want` is written here with K_b to four digits and 82.1 rounded.
        assert!((limit - want).abs() < 0.1, "{limit} vs {want}");
        emu.handle(&HostMsg::Identify);
        let id: BoardMsg = control::frame::decode_frame(&emu.take_output()).unwrap();
        assert!(
            matches!(id, BoardMsg::Identity { speed_max, .. } if speed_max == limit),
            "{id:?}"
        );
        use control::frame::Nack;
        assert_eq!(nack(&mut emu, 0.95 * limit), [BoardMsg::Ack]);
        for w in [1.01 * limit, -1.01 * limit, f32::NAN, f32::INFINITY] {
            assert_eq!(nack(&mut emu, w), [BoardMsg::Nack(Nack::OutOfRange)], "{w}");
        }
    }
}

#[test]
fn no_experiment_signal_exceeds_its_current_limit() {
    // The widest voltage limit with the default trip, a low trip, and a low trip at half
    // the voltage: the signals' sizes come from u_max in the first, from R·i_max in the
    // others.
    for (u_max, i_max) in [(24.0, 30.0), (24.0, 10.0), (12.0, 5.0)] {
        let co = paper_coefficients(u_max, i_max);
        let r_i = f64::from(co.motor.r * i_max);
        for (signal, paper_peak) in [
            (Excitation::A, 12.0),
            (Excitation::B, 6.0),
            (Excitation::C, 0.5),
            (Excitation::D, 10.0),
        ] {
            let mut emu = board_with(&co);
            emu.handle(&HostMsg::StartExperiment {
                signal,
                duration_s: 40.0,
            });
            let (p, fault) = run(&mut emu, 3300);
            let what = format!("{signal:?} at u_max {u_max} V, i_max {i_max} A");
            assert_eq!(fault, None, "{what}");
            // The signal itself stays inside the current window: a-c are never held at its
            // edge; d only in the period after a level change at speed (the measured-current
            // window lets the current rise by half its distance to the limit per period),
            // a few of its 3300 periods.
            let held = p
                .iter()
                .filter(|x| x.faults.contains(Faults::CURRENT_LIMIT))
                .count();
            let allowed = if signal == Excitation::D { 33 } else { 0 };
            assert!(held <= allowed, "{what}: held {held} periods");
            let peak = peak_current(&p);
            assert!(peak < i_limit(&co), "{what}: peak {peak} A");
            // Sized by the smaller of the two, P·u_lim/24 V and 0.35·R·i_max (a multisine's
            // Schroeder phases and slow envelope keep its largest sample near 0.4 of that).
            let u_lim = f64::from(u_max).min(0.95 * 22.2);
            let size = (paper_peak * u_lim / 24.0).min(0.35 * r_i);
            let top = p.iter().map(|x| f64::from(x.u.abs())).fold(0.0, f64::max);
            // 1e-4 V: the board's f32 signal against this f64 size; 0.3: the largest sample
            // sits near 0.4 of the size (above), so a signal shrunk by a quarter fails.
            assert!(
                top <= size + 1e-4 && top > 0.3 * size,
                "{what}: |u| {top} V of {size} V"
            );
        }
    }
}

/// Runs speed mode to `w` [rad/s] for `n` periods from where the board is now.
fn speed_run(emu: &mut EmulatedBoard, w: f32, n: usize) -> (Vec<Period>, Option<Fault>) {
    emu.handle(&HostMsg::SetSpeed { omega_ref: w });
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    run(emu, n)
}

#[test]
fn a_run_started_while_the_rotor_turns_holds_the_current_limit() {
    // Spin up to 200 rad/s, stop (the bridge turns off, the rotor coasts), then start the
    // next run at once: its first period's window must sit around the back-EMF of the
    // turning rotor (14 V), not around 0 V, which would brake with 65 A.
    let co = paper_coefficients(24.0, 30.0);
    let lim = i_limit(&co);
    type Start = fn(&mut EmulatedBoard);
    let starts: [(&str, Start); 4] = [
        ("speed 200", |s| {
            s.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
            s.handle(&HostMsg::SetMode { mode: Mode::Speed });
        }),
        ("speed without SetSpeed", |s| {
            s.handle(&HostMsg::SetMode { mode: Mode::Speed });
        }),
        ("steady 0.8 V", |s| {
            s.handle(&HostMsg::StartExperiment {
                signal: Excitation::Steady { volts: 0.8 },
                duration_s: 2.0,
            });
        }),
        ("signal a", |s| {
            s.handle(&HostMsg::StartExperiment {
                signal: Excitation::A,
                duration_s: 2.0,
            });
        }),
    ];
    for (what, start) in starts {
        let mut emu = board_with(&co);
        let (_, fault) = speed_run(&mut emu, 200.0, 250);
        assert_eq!(fault, None, "{what}");
        emu.handle(&HostMsg::Stop);
        let (coast, _) = run(&mut emu, 1);
        // Still turning fast: friction takes far less than 50 rad/s in one 12 ms period.
        assert!(coast[0].omega > 150.0, "{what}: {}", coast[0].omega);
        start(&mut emu);
        let (p, fault) = run(&mut emu, 150);
        let peak = peak_current(&p);
        eprintln!("{what}: peak {peak:.2} A after a start at 200 rad/s");
        assert_eq!(fault, None, "{what}: peak {peak} A");
        assert!(
            peak <= lim + margin(&co),
            "{what}: peak {peak} A, limit {lim} A + {} A",
            margin(&co)
        );
    }
}

#[test]
fn a_speed_run_without_its_own_setspeed_does_not_reuse_the_last_one() {
    let co = paper_coefficients(24.0, 30.0);
    let mut emu = board_with(&co);
    let (_, fault) = speed_run(&mut emu, 150.0, 200);
    assert_eq!(fault, None);
    emu.handle(&HostMsg::Stop);
    // An experiment does not see the old target: its reference follows the measured speed.
    emu.handle(&HostMsg::StartExperiment {
        signal: Excitation::Steady { volts: 0.0 },
        duration_s: 1.0,
    });
    run(&mut emu, 100);
    let w = emu.board().control().omega();
    // The reference is the estimate, copied each period: 1e-3 rad/s absorbs f32 rounding.
    assert!(
        (emu.board().speed_reference() - w).abs() < 1e-3,
        "reference {} vs ω̂ {w}",
        emu.board().speed_reference()
    );
    // A new speed run starts at the speed the rotor has and is asked for zero.
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    let (p, fault) = run(&mut emu, 400);
    assert_eq!(fault, None);
    let w = mean_speed(&p[350..]);
    // At rest within 2 rad/s: below the 0.79 rad/s estimate resolution the loop cannot
    // tell a creep from a standstill, and the mean of the true speed sees a few of those.
    assert!(w.abs() < 2.0, "{w} rad/s");
    assert_eq!(emu.board().speed_reference(), 0.0);
}

/// Periods that ended with the current beyond `i_max` (the current then stayed beyond
/// it for a whole period: the winding's L/R is 1.4 ms). The over-current check reads the
/// current once a period, so the period in which it crosses `i_max` can end beyond it
/// before the next period's check turns the bridge off: one such period, never two.
fn beyond_trip(p: &[Period], i_max: f64) -> usize {
    p.iter().filter(|x| x.end_i > i_max).count()
}

#[test]
fn wrong_motor_constants_in_the_blob_do_not_lift_the_current_limit() {
    // The emulated motor is the paper's; the blob's K_b, R or pole pairs are wrong. The
    // model's window alone lets through up to K_b·Δω/R more: K_b×2 at 100 rad/s is 33 A
    // beyond the limit, R×2 doubles it. The measured-current window holds the current at
    // the limit plus the margin (R 2× too high: the overshoot of g·ρ = 1.25 from rest,
    // the measured-current gain of one half keeps it within the limit), or a fault stops
    // the run; never beyond i_max for more than one period.
    let base = paper_coefficients(24.0, 10.0);
    let lim = i_limit(&base);
    let i_max = f64::from(base.limits.i_max);
    type Change = fn(&mut Coefficients);
    let cases: [(&str, Change); 5] = [
        ("K_b x2", |c| c.motor.kb *= 2.0),
        ("K_b x0.5", |c| c.motor.kb *= 0.5),
        ("R x2", |c| c.motor.r *= 2.0),
        ("5 pole pairs", |c| c.pole_pairs = 5),
        ("22 pole pairs", |c| c.pole_pairs = 22),
    ];
    for (what, change) in cases {
        let mut co = base.clone();
        change(&mut co);
        let allowed = lim + margin(&base);
        let mut emu = board_with(&co);
        let (mut p, mut fault) = speed_run(&mut emu, 100.0, 250);
        if fault.is_none() {
            let (q, f) = speed_run(&mut emu, -100.0, 300);
            p.extend(q);
            fault = f;
        }
        let peak = peak_current(&p);
        let over = beyond_trip(&p, i_max);
        eprintln!("{what}: peak {peak:.2} A (limit {lim} A), fault {fault:?}, {over} periods beyond i_max");
        // One period: the over-current check's delay (`beyond_trip`).
        assert!(over <= 1, "{what}: {over} periods beyond i_max");
        if fault.is_none() {
            assert!(peak <= allowed, "{what}: peak {peak} A of {allowed} A");
        }
        // The open-loop 20 V step, held by the window alone.
        let mut emu = board_with(&co);
        emu.handle(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 20.0 },
            duration_s: 2.0,
        });
        let (p, fault) = run(&mut emu, 150);
        let peak = peak_current(&p);
        let over = beyond_trip(&p, i_max);
        eprintln!("{what}, 20 V: peak {peak:.2} A, fault {fault:?}, {over} periods beyond i_max");
        // One period: the over-current check's delay (`beyond_trip`).
        assert!(over <= 1, "{what}, 20 V: {over} periods beyond i_max");
        if fault.is_none() {
            assert!(
                peak <= allowed,
                "{what}, 20 V: peak {peak} A of {allowed} A"
            );
        }
    }
}

#[test]
fn wrong_motor_constants_never_run_the_rotor_away() {
    // With K_b too high or the pole pairs wrong the model's window can lie wholly beside the
    // measured current's; the command then follows the measurement. Asked for +100 rad/s,
    // then -100 rad/s, the rotor either tracks the reference (in the blob's speed scale,
    // within 10 rad/s at the end of each run) or the board stops with a fault; its true
    // speed stays within 1.5 times the larger of the reference and its true equivalent,
    // and below the no-load speed at u_max (the runaway).
    let base = paper_coefficients(24.0, 10.0);
    let pp_true = f64::from(control::hall::PAPER_POLE_PAIRS);
    let runaway = 24.0 / f64::from(base.motor.kb);
    type Change = fn(&mut Coefficients);
    // The flag: the model's back-EMF lies below the motor's, so its window caps the voltage
    // and the rotor may fall short of the reference (never beyond it).
    let cases: [(&str, Change, bool); 5] = [
        ("K_b x2", |c| c.motor.kb *= 2.0, false),
        ("K_b x1.5", |c| c.motor.kb *= 1.5, false),
        ("K_b x0.5", |c| c.motor.kb *= 0.5, true),
        ("5 pole pairs", |c| c.pole_pairs = 5, false),
        ("22 pole pairs", |c| c.pole_pairs = 22, true),
    ];
    for (what, change, short) in cases {
        let mut co = base.clone();
        change(&mut co);
        // True speed [rad/s] per estimated speed: the estimate counts the blob's pole pairs.
        let scale = f64::from(co.pole_pairs) / pp_true;
        let bound = 1.5 * 100.0 * scale.max(1.0);
        let mut emu = board_with(&co);
        let mut fault = None;
        for w in [100.0f32, -100.0] {
            let (p, f) = speed_run(&mut emu, w, 400);
            let top = p.iter().map(|x| x.omega.abs()).fold(0.0, f64::max);
            let end = mean_speed(&p[350..]) / scale;
            let mismatched = p
                .iter()
                .filter(|x| x.faults.contains(Faults::MODEL_MISMATCH))
                .count();
            eprintln!("{what}, {w} rad/s: true top {top:.1} rad/s (bound {bound:.0}, runaway {runaway:.0}), end {end:.1} rad/s in the blob's scale, {mismatched} disjoint periods, fault {f:?}");
            assert!(top < bound && top < runaway, "{what}, {w}: top {top} rad/s");
            if f.is_some() {
                fault = f;
                break;
            }
            let w = f64::from(w);
            // 10 rad/s (10 %): tracking in direction and size with wrong constants; the
            // accuracy with correct ones is checked to 4 rad/s above.
            if short {
                assert!(
                    end * w > 0.0 && end.abs() < w.abs() + 10.0,
                    "{what}, {w}: {end} rad/s"
                );
            } else {
                assert!((end - w).abs() < 10.0, "{what}, {w}: {end} rad/s");
            }
        }
        if let Some(f) = fault {
            assert!(
                matches!(
                    f,
                    Fault::ModelMismatch | Fault::OverSpeed | Fault::Stall | Fault::CurrentSense
                ),
                "{what}: {f:?}"
            );
        }
    }
}

#[test]
fn a_model_back_emf_far_below_the_motors_stops_at_the_first_braking_period() {
    // K_b at 0.4 times the motor's, and a load that drives the rotor (0.4 N·m, within what
    // the current limit brakes): the true current brakes while the model's driving voltage
    // says it drives. The current looks implausible, and the model's window, which would
    // take over, lies beside the measured one: neither bounds the current, and the board
    // stops in that same period, before any period ends with the current beyond i_max.
    let mut co = paper_coefficients(24.0, 10.0);
    co.motor.kb *= 0.4;
    let i_max = f64::from(co.limits.i_max);
    let plant = EmulatorConfig::paper().with_extra_load(|x| if x.t > 0.5 { -0.8 } else { 0.0 });
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(&co).unwrap())
        .unwrap();
    let mut emu = EmulatedBoard::new(plant, Wiring::default(), slots.into_inner()).unwrap();
    let (p, fault) = speed_run(&mut emu, 20.0, 400);
    let over = beyond_trip(&p, i_max);
    let peak = peak_current(&p);
    let both = p.iter().position(|x| {
        x.faults.contains(Faults::CURRENT_SENSE) && x.faults.contains(Faults::MODEL_MISMATCH)
    });
    let sense = p
        .iter()
        .position(|x| x.faults.contains(Faults::CURRENT_SENSE));
    eprintln!("K_b x0.4, driving load: fault {fault:?}, peak {peak:.2} A, {over} periods beyond i_max, flagged first in period {sense:?}, with disjoint windows {both:?}");
    assert_eq!(fault, Some(Fault::CurrentSense), "peak {peak} A");
    assert_eq!(both, sense, "stopped in the first flagged period");
    assert_eq!(over, 0, "{over} periods beyond i_max, peak {peak} A");
    // From the fault on the bridge is off: the current decays within the next period.
    let k = both.unwrap();
    assert!(
        p[k + 2..].iter().all(|x| x.peak_i < 0.1),
        "{:?}",
        &p[k + 1..k + 3]
    );
}

#[test]
fn a_load_step_at_speed_holds_the_current_limit() {
    // At 150 rad/s a load rises to 0.6 N·m over 0.1 s (8.4 A of torque, beyond what the
    // limit's 8 A give with friction): the rotor slows while the moving average still
    // reports the old speed, so the model's window sits too high. The measured current
    // holds the limit.
    let co = paper_coefficients(24.0, 10.0);
    let lim = i_limit(&co);
    for (torque, rise, jam) in [(0.6, 0.1, false), (20.0, 0.0, true)] {
        let plant = EmulatorConfig::paper().with_extra_load(move |x| {
            let on = if rise > 0.0 {
                ((x.t - 1.5) / rise).clamp(0.0, 1.0)
            } else {
                f64::from(u8::from(x.t > 1.5))
            };
            on * torque * (x.omega / 5.0).clamp(-1.0, 1.0)
        });
        let mut slots = RamFlash::new(None).into_slots().unwrap();
        slots
            .store(&motorid::board::coeffs::encode(&co).unwrap())
            .unwrap();
        let mut emu = EmulatedBoard::new(plant, Wiring::default(), slots.into_inner()).unwrap();
        let (p, fault) = speed_run(&mut emu, 150.0, 300);
        let peak = peak_current(&p);
        let over = beyond_trip(&p, f64::from(co.limits.i_max));
        eprintln!("load {torque} N·m: peak {peak:.2} A (limit {lim} A), fault {fault:?}, {over} periods beyond i_max");
        // One period: the over-current check's delay (`beyond_trip`).
        assert!(over <= 1, "{torque} N·m: {over} periods beyond i_max");
        if jam {
            // A jam within one period cannot be held by a 12 ms loop: a fault stops it.
            assert!(fault.is_some(), "{torque} N·m: peak {peak} A");
        } else {
            // The stated margin: the load's torque grows for 8 periods and the rotor's
            // deceleration with it, faster than the back-EMF's trend of the last period
            // predicts; the current stays below the trip i_max (10 A), never faulting.
            assert_eq!(fault, None, "{torque} N·m");
            let i_max = f64::from(co.limits.i_max);
            assert!(peak < i_max, "{torque} N·m: peak {peak} A, trip {i_max} A");
            assert!(p[200..]
                .iter()
                .any(|x| x.faults.contains(Faults::CURRENT_LIMIT)));
        }
    }
}

#[test]
fn a_load_that_drives_the_motor_past_the_speed_limit_is_an_over_speed_fault() {
    // A 2 Ω winding (so that the bridge can still hold the braking current well past the
    // speed limit: `(K_b·ω − V_bus)/R` stays below i_max up to about 570 rad/s) at 200 rad/s,
    // then a load drives the rotor with 1.1 N·m, more than the current limit's 8 A can brake
    // (0.57 N·m). The speed estimate passes 1.25 times the speed limit and the board stops
    // with an over-speed fault before the current reaches its trip.
    let mut co = paper_coefficients(24.0, 10.0);
    co.motor.r = 2.0;
    let mut plant = EmulatorConfig::paper().with_extra_load(|x| if x.t > 1.5 { -1.1 } else { 0.0 });
    plant.motor.r = 2.0;
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(&co).unwrap())
        .unwrap();
    let mut emu = EmulatedBoard::new(plant, Wiring::default(), slots.into_inner()).unwrap();
    let w_max = f64::from(emu.board().speed_limit());
    emu.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    // Up to the fault: the true top speed, the estimate's and the peak current.
    let (mut top, mut top_est, mut peak, mut fault) = (0.0f64, 0.0f32, 0.0f64, None);
    for k in 0..400 {
        if k % 50 == 0 {
            emu.handle(&HostMsg::Heartbeat);
        }
        emu.tick();
        top = top.max(emu.hardware().plant().truth().omega);
        top_est = top_est.max(emu.board().last_step_outputs().omega);
        peak = peak.max(emu.hardware().peak_current());
        fault = emu.board().fault();
        if fault.is_some() {
            break;
        }
    }
    eprintln!("driving load: fault {fault:?}, top {top:.0} rad/s (estimate {top_est:.0}, limit {w_max:.0}), peak {peak:.2} A");
    assert_eq!(fault, Some(Fault::OverSpeed), "top {top} rad/s");
    let threshold = control::board::OVERSPEED_FACTOR * w_max as f32;
    assert!(top_est > threshold, "estimate {top_est} rad/s");
    assert!(peak < f64::from(co.limits.i_max), "peak {peak} A");
}

#[test]
fn the_speed_limit_follows_the_measured_bus_voltage() {
    // u_max 24 V: at the nominal 22.2 V the limit is 0.95·22.2/K_b = 296 rad/s; a bus
    // sagging to 14 V lowers it to 187 rad/s: the running reference comes down to it, a
    // SetSpeed beyond it is refused and the board reports it.
    let co = paper_coefficients(24.0, 30.0);
    let mut emu = board_with(&co);
    let nominal = emu.board().speed_limit();
    // The board evaluates the same f32 formula (MAX_DUTY·V_bus/K_b): 0.1 rad/s leaves
    // room for the order of its rounding only. Likewise for the low limit below.
    assert!(
        (nominal - 0.95 * 22.2 / co.motor.kb).abs() < 0.1,
        "{nominal}"
    );
    let (p, fault) = speed_run(&mut emu, 250.0, 150);
    assert_eq!(fault, None);
    // 2 % of the reference, as in the step test.
    assert!((mean_speed(&p[120..]) - 250.0).abs() < 5.0);
    emu.hardware_mut().set_bus_voltage(14.0);
    let (p, fault) = run(&mut emu, 150);
    assert_eq!(fault, None);
    let low = 0.95 * 14.0 / co.motor.kb;
    assert!(
        (emu.board().speed_limit() - low).abs() < 0.1,
        "{}",
        emu.board().speed_limit()
    );
    assert!(
        emu.board().speed_reference() <= low,
        "{}",
        emu.board().speed_reference()
    );
    let w = mean_speed(&p[120..]);
    // At its voltage limit the loop holds the speed friction leaves below the no-load one
    // (2 rad/s above: the estimate's resolution and the true speed's ripple; 0.85: friction
    // at 187 rad/s takes a few per cent of the no-load speed).
    assert!(
        w <= f64::from(low) + 2.0 && w > 0.85 * f64::from(low),
        "{w} rad/s"
    );
    emu.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
    let reply: BoardMsg = control::frame::decode_frame(&emu.take_output()).unwrap();
    assert_eq!(reply, BoardMsg::Nack(control::frame::Nack::OutOfRange));
    emu.handle(&HostMsg::Identify);
    let id: BoardMsg = control::frame::decode_frame(&emu.take_output()).unwrap();
    // 0.1 rad/s: the rounding room of the board's limit above.
    assert!(
        matches!(id, BoardMsg::Identity { speed_max, .. } if (speed_max - low).abs() < 0.1),
        "{id:?}"
    );
}

/// The board's replies since the last call.
fn replies(emu: &mut EmulatedBoard) -> Vec<BoardMsg> {
    emu.take_output()
        .split_inclusive(|&b| b == 0)
        .map(|f| control::frame::decode_frame(f).unwrap())
        .collect()
}

#[test]
fn without_an_armed_hardware_stop_nothing_that_drives_runs() {
    use control::frame::{Nack, Warning};
    let co = paper_coefficients(24.0, 30.0);
    for run_without in [false, true] {
        let mut emu = board_with(&co);
        emu.set_hardware_stop(false, run_without);
        assert_eq!(
            replies(&mut emu),
            [BoardMsg::Warning(Warning::NoHardwareStop)]
        );
        // Every later Identify reports it, not only the boot warning.
        emu.handle(&HostMsg::Identify);
        assert!(
            matches!(
                replies(&mut emu)[..],
                [BoardMsg::Identity {
                    hw_stop_armed: false,
                    ..
                }]
            ),
            "run_without {run_without}"
        );
        let want = if run_without {
            BoardMsg::Ack
        } else {
            BoardMsg::Nack(Nack::NoHardwareStop)
        };
        emu.handle(&HostMsg::StartExperiment {
            signal: Excitation::A,
            duration_s: 1.0,
        });
        assert_eq!(replies(&mut emu), std::slice::from_ref(&want), "experiment");
        emu.handle(&HostMsg::Stop);
        replies(&mut emu);
        emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
        assert_eq!(replies(&mut emu), std::slice::from_ref(&want), "speed");
        emu.handle(&HostMsg::Stop);
        replies(&mut emu);
        emu.handle(&HostMsg::Commission);
        assert_eq!(replies(&mut emu), [want], "commissioning");
    }
}

/// Voltage the emulated board's bridge loses to its dead time along a vector, at its
/// nominal bus voltage [V].
fn dead_time_drop() -> f64 {
    f64::from(control::board::dead_time_drop(
        motorid::board::emulated_board::V_BUS_NOMINAL,
    ))
}

/// Runs commissioning to its end (at most `n` periods) on a winding of line-to-line `r` [Ω]
/// behind a true drop `vd` [V]; returns the true peak current [A] and the largest current
/// [A] a resting rotor would draw at the voltages held, `(V − V_t)/(¾·R)`.
fn commission(emu: &mut EmulatedBoard, n: usize, (vd, r): (f64, f64)) -> (f64, f64) {
    replies(emu);
    emu.handle(&HostMsg::Commission);
    let (mut peak, mut at_rest) = (0.0f64, 0.0f64);
    for _ in 0..n {
        emu.tick();
        peak = peak.max(emu.hardware().peak_current());
        let v = emu.hardware().last_volts();
        at_rest = at_rest.max((v - vd).max(0.0) / (0.75 * r));
        if emu.board().mode() == Mode::Idle {
            break;
        }
    }
    (peak, at_rest)
}

#[test]
fn commissioning_holds_its_current_at_rest_on_a_winding_far_below_the_blobs_r() {
    // The default blob's R is 0.22 Ω; windings of a quarter of it, of 20 mΩ and of the
    // ramp's smallest designed R would take four, eleven and twenty-two times the
    // commissioning current at the voltage sized from the blob. The first hold's ramp steps
    // only while the rotor rests, meets the measured current from below and stops short of
    // the limit: the run still learns the wiring and R.
    for r_true in [
        0.25 * control::motor::MotorParams::<f64>::paper().r,
        0.02,
        f64::from(control::commission::RAMP_R_MIN),
    ] {
        let mut plant = EmulatorConfig::paper();
        plant.motor.r = r_true;
        plant.effects.push(Effect::Deadtime {
            vd: dead_time_drop(),
        });
        let vd = dead_time_drop();
        let mut emu = EmulatedBoard::new(plant, Wiring::default(), RamFlash::new(None)).unwrap();
        let i_comm = f64::from(emu.board().commission_current());
        let (peak, at_rest) = commission(&mut emu, 900, (vd, r_true));
        let co = emu.coefficients().clone();
        let r = f64::from(co.motor.r);
        eprintln!("{r_true} Ω winding: commissioning {at_rest:.2} A at rest, true peak {peak:.2} A (its limit {i_comm:.1} A), R {r:.4} Ω");
        // At the ramp's smallest designed R only the current is checked: this motor's
        // back-EMF then holds the rotor to a creep through whole holds (decision 0023).
        if r_true > f64::from(control::commission::RAMP_R_MIN) {
            assert!(co.commission.is_some(), "{r_true} Ω: commissioning failed");
            // 10 %: R is the slope between two held levels of the noisy current sense; its
            // uses (the current window, sized experiments) need it to about that.
            assert!((r - r_true).abs() < 0.1 * r_true, "R {r} vs {r_true}");
        }
        // 1e-3: the f32 voltages' rounding.
        assert!(
            at_rest <= i_comm * (1.0 + 1e-3),
            "{r_true} Ω: {at_rest} A at rest, limit {i_comm} A"
        );
    }
}

#[test]
fn a_current_sense_that_sees_no_current_fails_commissioning_and_keeps_the_blob() {
    // A dead sense (reads nothing) and one that reads only noise (50 mA) on a board whose
    // flash holds coefficients: the ramp never measures a current above its floor and the
    // run ends with RampStalled, nothing is stored, R and the sense sign are not taken from
    // noise.
    let co = paper_coefficients(24.0, 30.0);
    for noise in [0.0, 0.05] {
        let mut plant = EmulatorConfig::paper();
        plant.current_noise = noise;
        let mut slots = RamFlash::new(None).into_slots().unwrap();
        slots
            .store(&motorid::board::coeffs::encode(&co).unwrap())
            .unwrap();
        let mut emu = EmulatedBoard::new(plant, Wiring::default(), slots.into_inner()).unwrap();
        emu.hardware_mut().set_current_sense_gain(0.0);
        let seq = emu.coeff_seq();
        let (peak, _) = commission(&mut emu, 900, (0.0, f64::from(co.motor.r)));
        emu.handle(&HostMsg::ReadCommission);
        let out = replies(&mut emu);
        eprintln!("dead sense, noise {noise} A: {out:?}, peak {peak:.2} A");
        assert!(
            out.iter().any(|m| matches!(
                m,
                BoardMsg::Commission {
                    outcome: CommissionOutcome::Failed(CommissionError::RampStalled),
                    ..
                }
            )),
            "noise {noise}: {out:?}"
        );
        assert_eq!(emu.coeff_seq(), seq, "noise {noise}: stored");
        assert_eq!(emu.coefficients(), &co, "noise {noise}");
    }
}

#[test]
fn commissioning_measures_r_and_its_default_motor_allows_no_speed_mode() {
    use control::frame::Nack;
    // An emulated motor with twice the default winding resistance, behind a bridge
    // whose dead time takes its drop from the voltage, on a board without coefficients.
    let mut plant = EmulatorConfig::paper();
    plant.motor.r *= 2.0;
    plant.effects.push(Effect::Deadtime {
        vd: dead_time_drop(),
    });
    let r_true = plant.motor.r;
    let mut emu = EmulatedBoard::new(plant, Wiring::default(), RamFlash::new(None)).unwrap();
    replies(&mut emu);
    emu.handle(&HostMsg::Commission);
    for _ in 0..900 {
        emu.tick();
        if emu.coeff_seq() != 0 {
            break;
        }
    }
    assert_ne!(emu.coeff_seq(), 0, "commissioning did not store");
    let co = emu.coefficients().clone();
    assert!(!co.motor_identified);
    let r = f64::from(co.motor.r);
    eprintln!("commissioning measured R = {r:.4} Ω (true {r_true:.4} Ω)");
    // 10 %, as above.
    assert!((r - r_true).abs() < 0.1 * r_true, "R {r} vs {r_true}");
    replies(&mut emu);
    emu.handle(&HostMsg::Identify);
    assert!(matches!(
        replies(&mut emu)[..],
        [BoardMsg::Identity {
            motor_identified: false,
            ..
        }]
    ));
    // Speed mode is refused on the default constants; a sized experiment runs, and its
    // current window uses the measured R.
    emu.handle(&HostMsg::SetSpeed { omega_ref: 50.0 });
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    assert_eq!(
        replies(&mut emu),
        [BoardMsg::Ack, BoardMsg::Nack(Nack::MotorNotIdentified)]
    );
    emu.handle(&HostMsg::StartExperiment {
        signal: Excitation::Steady { volts: 10.0 },
        duration_s: 1.0,
    });
    assert_eq!(replies(&mut emu), [BoardMsg::Ack]);
    let (p, fault) = run(&mut emu, 80);
    assert_eq!(fault, None);
    let lim = i_limit(&co);
    let peak = peak_current(&p);
    assert!(peak <= lim + margin(&co), "peak {peak} A, limit {lim} A");
}

#[test]
fn an_inverted_current_sense_without_commissioning_stops_near_the_current_limit() {
    // Without a commissioning result the board takes the sense's sign as +1; inverted, the
    // measured-current window would feed the current back positively. The board sees the
    // measured current flow against the voltage driving it, bounds the command by the
    // model's window alone and stops with a current-sense fault within a few periods: the
    // true current never goes much beyond the standing limit, let alone the trip.
    let co = paper_coefficients(24.0, 10.0);
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(&co).unwrap())
        .unwrap();
    let wiring = Wiring {
        current_inverted: true,
        ..Wiring::default()
    };
    let mut emu = EmulatedBoard::new(EmulatorConfig::paper(), wiring, slots.into_inner()).unwrap();
    let (p, fault) = speed_run(&mut emu, 100.0, 20);
    let peak = peak_current(&p);
    let lim = i_limit(&co);
    let first = p
        .iter()
        .position(|x| x.faults.contains(Faults::CURRENT_SENSE))
        .expect("the implausible current is flagged");
    let stop = first + control::board::CURRENT_SENSE_PERIODS as usize;
    eprintln!(
        "inverted sense: fault {fault:?} after {stop} periods, peak {peak:.2} A, limit {lim:.1} A"
    );
    assert_eq!(fault, Some(Fault::CurrentSense), "peak {peak} A");
    // The sign is wrong from the first period the current flows: flagged by the second
    // period, then CURRENT_SENSE_PERIODS (3) in a row to the fault.
    assert!(stop <= 5, "flagged first in period {first}");
    assert!(peak <= lim + margin(&co), "peak {peak} A, limit {lim} A");
    // After the fault the bridge is off: the current decays to nothing.
    // 0.1 A: a current that had not decayed would still be amperes (L/R is 1.4 ms).
    assert!(p.last().unwrap().end_i < 0.1, "{:?}", p.last());

    // An open-loop experiment from rest (a steady 10 V, far above the 1.7 V that drive the
    // limit at standstill) goes through the same window: the same stop.
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(&co).unwrap())
        .unwrap();
    let mut emu = EmulatedBoard::new(EmulatorConfig::paper(), wiring, slots.into_inner()).unwrap();
    emu.handle(&HostMsg::StartExperiment {
        signal: Excitation::Steady { volts: 10.0 },
        duration_s: 1.0,
    });
    let (p, fault) = run(&mut emu, 20);
    let peak = peak_current(&p);
    eprintln!("inverted sense, steady 10 V: fault {fault:?}, peak {peak:.2} A");
    assert_eq!(fault, Some(Fault::CurrentSense), "peak {peak} A");
    assert!(peak <= lim + margin(&co), "peak {peak} A, limit {lim} A");
}

#[test]
fn a_speed_asked_during_an_experiment_is_dropped_when_it_ends() {
    let co = paper_coefficients(24.0, 30.0);
    let mut emu = board_with(&co);
    emu.handle(&HostMsg::StartExperiment {
        signal: Excitation::Steady { volts: 0.0 },
        duration_s: 0.24,
    });
    emu.handle(&HostMsg::SetSpeed { omega_ref: 150.0 });
    let (_, fault) = run(&mut emu, 40);
    assert_eq!(fault, None);
    // The experiment ended by its duration; a speed run now starts from a zero target.
    emu.handle(&HostMsg::SetMode { mode: Mode::Speed });
    let (p, fault) = run(&mut emu, 100);
    assert_eq!(fault, None);
    let top = p.iter().map(|x| x.omega.abs()).fold(0.0, f64::max);
    // The 150 rad/s target would show at once; 2 rad/s is a creep from the zero target.
    assert!(top < 2.0, "{top} rad/s");
    assert_eq!(emu.board().speed_reference(), 0.0);
}

/// One commissioning run on the emulated board without coefficients (the default blob),
/// the rotor resting `start` Hall sectors from the first centre vector's field, on the
/// paper's motor with the winding's line-to-line `r` [Ω] and `l` [H], a true dead-time drop
/// of `drop` times the board's estimate and Coulomb friction `friction` [N·m] alone, its
/// current sense with noise of standard deviation `noise` [A] and an offset `offset` [A].
/// Returns the largest current [A] a resting rotor would draw at the voltages held,
/// `(V − V_t)/(¾·R)`, the largest true current [A] and the outcome.
fn commission_on(
    (r, l, drop, friction): (f64, f64, f64, f64),
    start: f64,
    (noise, offset): (f64, f64),
) -> (f64, f64, CommissionOutcome) {
    let mut plant = EmulatorConfig::paper();
    plant.current_noise = noise;
    if offset != 0.0 {
        plant.effects.push(Effect::CurrentOffset { i0: offset });
    }
    plant.motor.r = r;
    plant.motor.l = l;
    plant.lugre.alpha0 = friction;
    plant.lugre.alpha1 = 0.0;
    plant.lugre.alpha2 = 0.0;
    let vd = drop * dead_time_drop();
    plant.effects.push(Effect::Deadtime { vd });
    let sector = std::f64::consts::TAU / (6.0 * f64::from(plant.pole_pairs));
    let mut emu = EmulatedBoard::new(plant, Wiring::default(), RamFlash::new(None)).unwrap();
    emu.hardware_mut().place_rotor(start * sector);
    replies(&mut emu);
    emu.handle(&HostMsg::Commission);
    let (mut at_rest, mut peak) = (0.0f64, 0.0f64);
    // The longest run, and then some.
    let periods = usize::from(control::commission::RUN_PERIODS_MAX)
        + usize::from(control::commission::HOLD_PERIODS);
    for _ in 0..periods {
        emu.tick();
        peak = peak.max(emu.hardware().peak_current());
        let v = emu.hardware().last_volts();
        at_rest = at_rest.max((v - vd).max(0.0) / (0.75 * r));
        if emu.board().mode() == Mode::Idle {
            break;
        }
    }
    emu.handle(&HostMsg::ReadCommission);
    let outcome = replies(&mut emu)
        .into_iter()
        .find_map(|m| match m {
            BoardMsg::Commission { outcome, .. } => Some(outcome),
            _ => None,
        })
        .unwrap();
    (at_rest, peak, outcome)
}

#[test]
fn a_rotor_creeping_below_the_current_floor_keeps_the_commissioning_current_at_rest() {
    // The smallest designed winding R, 10 mΩ, with L 0.05 mH (L/R 0.4 periods) and a
    // low-friction rotor (0.005 N·m: it breaks away and creeps at about 0.1 A, below the
    // ramp's current floor) starting anywhere from the first field's centre to near its
    // unstable point, behind the estimated drop and the ends of the drop's range. The
    // current a resting rotor draws at every voltage held stays within the limit.
    let i_comm = {
        let emu = EmulatedBoard::new(
            EmulatorConfig::paper(),
            Wiring::default(),
            RamFlash::new(None),
        )
        .unwrap();
        f64::from(emu.board().commission_current())
    };
    let mut top = 0.0f64;
    for drop in [0.5, 1.0, 2.0] {
        for start in [0.0, 1.0, 2.0, 2.9, 4.0] {
            let sense = (EmulatorConfig::paper().current_noise, 0.0);
            let (at_rest, peak, out) = commission_on((0.01, 0.05e-3, drop, 0.005), start, sense);
            eprintln!(
                "drop {drop}x, start {start} sectors: {at_rest:.2} A at rest, true peak {peak:.2} A \
                 (limit {i_comm:.1} A), {out:?}"
            );
            // 1e-3: the f32 voltages' rounding, far below the margins the ramp keeps.
            assert!(
                at_rest <= i_comm * (1.0 + 1e-3),
                "drop {drop}x, start {start}: {at_rest} A at rest > {i_comm} A"
            );
            assert!(
                peak <= PEAK_SHARE * i_comm,
                "drop {drop}x, start {start}: true peak {peak} A"
            );
            top = top.max(at_rest);
        }
    }
    // The ramp does not buy the bound by never driving (the test could fail by a ramp that
    // never moves).
    assert!(top > 0.5 * i_comm, "largest current at rest {top} A");
}

/// Largest true current over the commissioning limit a run may reach, as a share of it: the
/// ramp bounds the current of a resting rotor only, and a rotor swinging past a centre adds
/// its back-EMF for a moment (decision 0023: up to 1.14 times on the reviewer's physical
/// model). Loose, so that it catches a ramp that overshoots, not the swing.
const PEAK_SHARE: f64 = 1.25;

/// The default blob's commissioning limit [A] on the emulated board.
fn commission_limit() -> f64 {
    let emu = EmulatedBoard::new(
        EmulatorConfig::paper(),
        Wiring::default(),
        RamFlash::new(None),
    )
    .unwrap();
    f64::from(emu.board().commission_current())
}

/// Runs `cases` of (R [Ω], drop ratio, friction [N·m], start [sectors], sense noise [A],
/// sense offset [A]) at L/R of one control period and checks the current at rest against
/// the limit and the true peak against [`PEAK_SHARE`] of it; returns the largest current at
/// rest [A].
fn check_commission_cases(cases: &[(f64, f64, f64, f64, f64, f64)]) -> f64 {
    let i_comm = commission_limit();
    let mut top = 0.0f64;
    for &(r, drop, friction, start, noise, offset) in cases {
        let l = r * f64::from(control::CONTROL_PERIOD_S);
        let (at_rest, peak, out) = commission_on((r, l, drop, friction), start, (noise, offset));
        let case = format!(
            "{r} Ω, drop {drop}x, {friction} N·m, start {start}, sense σ {noise} A + {offset} A"
        );
        eprintln!("{case}: {at_rest:.2} A at rest, true peak {peak:.2} A, {out:?}");
        // 1e-3: the f32 voltages' rounding. The target's 10 % margin covers a sense reading
        // up to (1 − 0.9)·limit/1.25 = 0.72 A low (decision 0023), seven times the largest σ.
        assert!(
            at_rest <= i_comm * (1.0 + 1e-3),
            "{case}: {at_rest} A at rest > {i_comm} A"
        );
        assert!(peak <= PEAK_SHARE * i_comm, "{case}: true peak {peak} A");
        top = top.max(at_rest);
    }
    top
}

#[test]
fn a_rotor_creeping_above_the_current_floor_keeps_the_commissioning_current_at_rest() {
    // Friction 0.01-0.05 N·m: at 10-20 mΩ a creep draws 0.2 A or more, above the ramp's
    // current floor, while the back-EMF hides amperes; the rotor starts near the first
    // field's unstable point (2.9 sectors) or half-way (1.5).
    let noise = EmulatorConfig::paper().current_noise;
    let mut cases = Vec::new();
    for r in [0.01, 0.02] {
        for drop in [0.5, 2.0] {
            for friction in [0.01, 0.03, 0.05] {
                for start in [1.5, 2.9] {
                    cases.push((r, drop, friction, start, noise, 0.0));
                }
            }
        }
    }
    let top = check_commission_cases(&cases);
    assert!(
        top > 0.5 * commission_limit(),
        "largest current at rest {top} A"
    );
}

#[test]
fn a_noisy_or_offset_current_sense_keeps_the_commissioning_current_at_rest() {
    // A sense with 0.05 and 0.1 A of noise (two and five times the emulator's), and one
    // reading 0.15 A high, on 10-20 mΩ with little and mid-band friction.
    let mut cases = Vec::new();
    for r in [0.01, 0.02] {
        for (noise, offset) in [(0.05, 0.0), (0.1, 0.0), (0.02, 0.15)] {
            for (drop, friction) in [(1.0, 0.005), (2.0, 0.03)] {
                cases.push((r, drop, friction, 2.9, noise, offset));
            }
        }
    }
    let top = check_commission_cases(&cases);
    assert!(
        top > 0.5 * commission_limit(),
        "largest current at rest {top} A"
    );
}

#[test]
#[ignore = "a sweep of minutes: run with COMMISSION_SWEEP=1 and --ignored"]
fn commissioning_sweep_over_r_lag_drop_friction_and_start() {
    // Decision 0023's figures: R 10-200 mΩ, L/R 0.42, 1 and 3 periods, drops 0.5-2x,
    // friction 0.005-0.08 N·m, six starts; prints one line a run and a summary.
    if std::env::var_os("COMMISSION_SWEEP").is_none() {
        return;
    }
    let i_comm = commission_limit();
    let (mut worst, mut peak_worst, mut stalled, mut learned, mut n) = (0.0f64, 0.0f64, 0, 0, 0);
    for r in [0.01, 0.02, 0.05, 0.1, 0.216] {
        for lag in [0.42, 1.0, 3.0] {
            for drop in [0.5, 1.0, 2.0] {
                for friction in [0.005, 0.01, 0.02, 0.03, 0.05, 0.08] {
                    for start in [0.0, 1.0, 1.5, 2.0, 2.5, 2.9] {
                        let l = lag * r * f64::from(control::CONTROL_PERIOD_S);
                        let sense = (EmulatorConfig::paper().current_noise, 0.0);
                        let (at_rest, peak, out) =
                            commission_on((r, l, drop, friction), start, sense);
                        println!(
                            "{r} {lag} {drop} {friction} {start} {:.3} {:.3} {out:?}",
                            at_rest / i_comm,
                            peak / i_comm
                        );
                        worst = worst.max(at_rest / i_comm);
                        peak_worst = peak_worst.max(peak / i_comm);
                        n += 1;
                        match out {
                            CommissionOutcome::Failed(CommissionError::RampStalled) => stalled += 1,
                            CommissionOutcome::Done(_) => learned += 1,
                            _ => {}
                        }
                    }
                }
            }
        }
    }
    println!(
        "{n} runs: at rest at most {worst:.3}x the limit, true peak {peak_worst:.3}x, \
         {stalled} RampStalled, {learned} learned"
    );
}

/// Runs commissioning on the emulated `plant` (its winding R and the dead-time drop `drop`
/// times the board's estimate taken from it, Coulomb friction `friction` [N·m] alone, the
/// rotor placed `start` sectors on) with `co` in flash. Returns the largest current [A] a
/// resting rotor would draw at the voltages held, the largest true current [A], the
/// outcome, the periods the run took and whether the flash was written.
fn commission_blob(
    mut plant: EmulatorConfig,
    co: &Coefficients,
    (drop, friction, start): (f64, f64, f64),
) -> (f64, f64, CommissionOutcome, usize, bool) {
    let r = plant.motor.r;
    plant.lugre.alpha0 = friction;
    plant.lugre.alpha1 = 0.0;
    plant.lugre.alpha2 = 0.0;
    let vd = drop * dead_time_drop();
    plant.effects.push(Effect::Deadtime { vd });
    let sector = std::f64::consts::TAU / (6.0 * f64::from(plant.pole_pairs));
    let mut slots = RamFlash::new(None).into_slots().unwrap();
    slots
        .store(&motorid::board::coeffs::encode(co).unwrap())
        .unwrap();
    let mut emu = EmulatedBoard::new(plant, Wiring::default(), slots.into_inner()).unwrap();
    emu.hardware_mut().place_rotor(start * sector);
    let seq = emu.coeff_seq();
    replies(&mut emu);
    emu.handle(&HostMsg::Commission);
    let (mut at_rest, mut peak, mut periods) = (0.0f64, 0.0f64, 0usize);
    let n = usize::from(control::commission::RUN_PERIODS_MAX)
        + usize::from(control::commission::HOLD_PERIODS);
    for k in 0..n {
        emu.tick();
        peak = peak.max(emu.hardware().peak_current());
        let v = emu.hardware().last_volts();
        at_rest = at_rest.max((v - vd).max(0.0) / (0.75 * r));
        periods = k + 1;
        if emu.board().mode() == Mode::Idle {
            break;
        }
    }
    emu.handle(&HostMsg::ReadCommission);
    let outcome = replies(&mut emu)
        .into_iter()
        .find_map(|m| match m {
            BoardMsg::Commission { outcome, .. } => Some(outcome),
            _ => None,
        })
        .unwrap();
    (at_rest, peak, outcome, periods, emu.coeff_seq() != seq)
}

/// The paper's coefficients (30 A, so a 9 A commissioning current) stating the back-EMF
/// and torque constant `kb` [V·s/rad] over `pole_pairs`.
fn coefficients_with_kb(kb: f32, pole_pairs: u8) -> Coefficients {
    let mut co = paper_coefficients(24.0, 30.0);
    co.motor.kb = kb;
    co.motor.kt = kb;
    co.pole_pairs = pole_pairs;
    co
}

#[test]
fn a_blob_with_a_large_back_emf_constant_commissions_its_own_motor() {
    // A motor with K_b 0.2 V·s/rad (2.8 and 7.7 times the stated constant per pole pair at
    // 11 and 4 pole pairs) on the blob's own R, 0.22 Ω, and its correct blob: the ramp
    // reaches its current and the run learns the table, within the limit at rest, from two
    // starts behind the ends of the drop's range.
    let i_comm = commission_limit();
    for pole_pairs in [11u8, 4] {
        let co = coefficients_with_kb(0.2, pole_pairs);
        let mut plant = EmulatorConfig::paper();
        plant.motor.kb = 0.2;
        plant.motor.kt = 0.2;
        plant.pole_pairs = u16::from(pole_pairs);
        for drop in [0.5, 2.0] {
            for start in [0.0, 2.9] {
                let (at_rest, peak, out, periods, stored) =
                    commission_blob(plant.clone(), &co, (drop, 0.03, start));
                let case = format!("{pole_pairs} pole pairs, drop {drop}x, start {start}");
                eprintln!(
                    "{case}: {at_rest:.2} A at rest, true peak {peak:.2} A, {periods} periods, \
                     {out:?}"
                );
                assert!(
                    matches!(out, CommissionOutcome::Done(_)) && stored,
                    "{case}: {out:?}"
                );
                // 1e-3: the f32 voltages' rounding.
                assert!(
                    at_rest <= i_comm * (1.0 + 1e-3),
                    "{case}: {at_rest} A at rest > {i_comm} A"
                );
                assert!(peak <= PEAK_SHARE * i_comm, "{case}: true peak {peak} A");
            }
        }
    }
}

#[test]
fn a_blob_overstating_the_back_emf_constant_keeps_the_commissioning_current_at_rest() {
    // The paper's motor (K_b 0.071 V·s/rad) at 10 and 20 mΩ behind blobs stating K_b 0.2
    // V·s/rad over 11 pole pairs, and the largest ratio the board starts a run for, with
    // the blob's default R (0.22 Ω): the ramp takes a larger R only from what its samples
    // show, and a resting rotor stays within the limit.
    let i_comm = commission_limit();
    let k_max = f32::from(control::commission::RAMP_K_RATIO_MAX) * control::commission::RAMP_K_EMF;
    let mut top = 0.0f64;
    for kb in [0.2, 11.0 * k_max] {
        let co = coefficients_with_kb(kb, 11);
        for r in [0.01, 0.02] {
            let mut plant = EmulatorConfig::paper();
            plant.motor.r = r;
            plant.motor.l = 0.42 * r * f64::from(control::CONTROL_PERIOD_S);
            for (drop, friction, start) in [(0.5, 0.005, 0.0), (1.0, 0.03, 2.9), (2.0, 0.005, 2.9)]
            {
                let (at_rest, peak, out, periods, _) =
                    commission_blob(plant.clone(), &co, (drop, friction, start));
                let case =
                    format!("blob K_b {kb}, {r} Ω, drop {drop}x, {friction} N·m, start {start}");
                eprintln!(
                    "{case}: {at_rest:.2} A at rest, true peak {peak:.2} A, {periods} periods, \
                     {out:?}"
                );
                // 1e-3: the f32 voltages' rounding.
                assert!(
                    at_rest <= i_comm * (1.0 + 1e-3),
                    "{case}: {at_rest} A at rest > {i_comm} A"
                );
                assert!(peak <= PEAK_SHARE * i_comm, "{case}: true peak {peak} A");
                top = top.max(at_rest);
            }
        }
    }
    assert!(top > 0.5 * i_comm, "largest current at rest {top} A");
}

#[test]
fn a_blob_with_kb_in_other_units_is_refused_before_anything_is_driven() {
    // 7.91 for 7.91/111 V·s/rad: 111 times the constant, past the largest ratio.
    let co = coefficients_with_kb(7.91, 11);
    let (at_rest, peak, out, periods, stored) =
        commission_blob(EmulatorConfig::paper(), &co, (1.0, 0.03, 2.0));
    assert_eq!(
        out,
        CommissionOutcome::Failed(CommissionError::BackEmfTooLarge)
    );
    assert!(!stored);
    assert_eq!((at_rest, peak), (0.0, 0.0), "after {periods} periods");
}
