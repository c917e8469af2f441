//! The board's limits on the emulated board, through the firmware's own logic
//! (`control::board::Board` in `motorid::board::sim::BoardSim`): the standing current limit,
//! the speed ramp, the speed limit and the size of the experiment signals.
use control::blob::{Coefficients, ModelKind, DERATE_FRACTION};
use control::frame::{BoardMsg, Excitation, Fault, HostMsg, Mode};
use control::lugre::LugreParams;
use control::step::Faults;
use motorid::board::flash::{RamFlash, PAGE};
use motorid::board::hw::Wiring;
use motorid::board::sim::BoardSim;
use motorid::emulator::EmulatorConfig;

/// The paper's motor with its LuGre compensation, as `motorid export` writes it for the
/// emulated motor, with the voltage limit `u_max` [V] and the current trip `i_max` [A].
fn paper_coefficients(u_max: f32, i_max: f32) -> Coefficients {
    let mut co = Coefficients {
        model: ModelKind::Lugre,
        lugre: Some(LugreParams::paper()),
        ..Coefficients::default()
    };
    co.pi.u_max = u_max;
    co.limits.i_max = i_max;
    co
}

/// The emulated paper motor on a board whose flash holds `co`.
fn board_with(co: &Coefficients) -> BoardSim {
    let mut slots = control::slots::Slots::new(RamFlash::new(None), 0, PAGE as u32).unwrap();
    slots
        .store(&motorid::board::coeffs::encode(co).unwrap())
        .unwrap();
    let sim = BoardSim::new(
        EmulatorConfig::paper(),
        Wiring::default(),
        slots.into_inner(),
    );
    sim.unwrap()
}

/// What one period showed: the true peak current [A] within it, the true speed at its end
/// [rad/s], the step's flags and the commanded voltage [V].
#[derive(Debug, Clone, Copy)]
struct Period {
    peak_i: f64,
    omega: f64,
    faults: Faults,
    u: f32,
}

/// Runs `n` periods with a heartbeat now and then; returns each period and the first fault.
fn run(sim: &mut BoardSim, n: usize) -> (Vec<Period>, Option<Fault>) {
    let mut periods = Vec::new();
    let mut fault = None;
    for k in 0..n {
        if k % 50 == 0 {
            sim.handle(&HostMsg::Heartbeat);
        }
        sim.tick();
        let out = *sim.board().last_step_outputs();
        periods.push(Period {
            peak_i: sim.hardware().peak_current(),
            omega: sim.hardware().plant().truth().omega,
            faults: out.faults,
            u: out.v_cmd,
        });
        fault = fault.or(sim.board().fault());
        let _ = sim.take_output();
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
        let mut sim = board_with(&co);
        sim.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
        sim.handle(&HostMsg::SetMode { mode: Mode::Speed });
        let (p, fault) = run(&mut sim, 300);
        assert_eq!(fault, None, "speed, i_max {i_max}");
        let peak = peak_current(&p);
        assert!(
            peak <= lim + margin(&co),
            "speed, i_max {i_max}: peak {peak} A, limit {lim} A + {} A",
            margin(&co)
        );
        let w = mean_speed(&p[250..]);
        assert!((w - 200.0).abs() < 4.0, "speed, i_max {i_max}: {w} rad/s");
        // The PI did not wind up while the window held it: no overshoot to speak of.
        let top = p.iter().map(|x| x.omega).fold(0.0, f64::max);
        assert!(
            top < 205.0,
            "speed, i_max {i_max}: overshoot to {top} rad/s"
        );
        if i_max == 10.0 {
            // The ramp alone would ask 8 A of acceleration and friction: the limit acts.
            assert!(peak > 0.85 * lim, "speed, i_max {i_max}: peak {peak} A");
            assert!(p.iter().any(|x| x.faults.contains(Faults::CURRENT_LIMIT)));
        }

        let mut sim = board_with(&co);
        sim.handle(&HostMsg::StartExperiment {
            signal: Excitation::Steady { volts: 20.0 },
            duration_s: 4.0,
        });
        let (p, fault) = run(&mut sim, 300);
        assert_eq!(fault, None, "20 V, i_max {i_max}");
        let peak = peak_current(&p);
        assert!(
            peak <= lim + margin(&co) && peak > 0.95 * lim,
            "20 V, i_max {i_max}: peak {peak} A, limit {lim} A + {} A",
            margin(&co)
        );
        // Held at the limit while it speeds up, then free: near the no-load speed of 20 V.
        assert!(p[..5]
            .iter()
            .all(|x| x.faults.contains(Faults::CURRENT_LIMIT)));
        let w = mean_speed(&p[250..]);
        let no_load = 20.0 / f64::from(co.motor.kb);
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
    // 0.5·K_t·8 A/J = 950 rad/s²: 11.4 rad/s per period.
    assert!((accel - 0.5 * 0.07126 * 8.0 / 3e-4).abs() < 1.0, "{accel}");
    let mut sim = board_with(&co);
    sim.handle(&HostMsg::SetSpeed { omega_ref: 200.0 });
    sim.handle(&HostMsg::SetMode { mode: Mode::Speed });
    let mut refs = vec![0.0f32];
    let mut periods = Vec::new();
    for k in 0..600 {
        if k == 300 {
            sim.handle(&HostMsg::SetSpeed { omega_ref: -200.0 });
        }
        let (p, fault) = run(&mut sim, 1);
        assert_eq!(fault, None, "period {k}");
        periods.extend(p);
        refs.push(sim.board().speed_reference());
    }
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
    assert!((refs[1] - per_period).abs() < 1e-4, "{}", refs[1]);
    assert!(
        refs[up - 1] < 200.0 && refs[up] == 200.0,
        "{:?}",
        &refs[..up + 1]
    );
    let down = 300 + (400.0 / per_period).ceil() as usize;
    assert!(refs[down - 1] > -200.0 && refs[down] == -200.0);
    // The motor follows, and braking through the reversal holds the current limit too.
    assert!((mean_speed(&periods[250..300]) - 200.0).abs() < 4.0);
    assert!((mean_speed(&periods[550..]) + 200.0).abs() < 4.0);
    let peak = peak_current(&periods);
    assert!(peak <= i_limit(&co) + margin(&co), "peak {peak} A");
}

#[test]
fn speed_references_beyond_the_speed_limit_are_refused() {
    let nack = |sim: &mut BoardSim, w: f32| {
        sim.handle(&HostMsg::SetSpeed { omega_ref: w });
        let out = sim.take_output();
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
        let mut sim = board_with(&co);
        let _ = sim.take_output();
        let limit = sim.board().speed_limit();
        assert!((limit - want).abs() < 0.1, "{limit} vs {want}");
        sim.handle(&HostMsg::Identify);
        let id: BoardMsg = control::frame::decode_frame(&sim.take_output()).unwrap();
        assert!(
            matches!(id, BoardMsg::Identity { speed_max, .. } if speed_max == limit),
            "{id:?}"
        );
        use control::frame::Nack;
        assert_eq!(nack(&mut sim, 0.95 * limit), [BoardMsg::Ack]);
        for w in [1.01 * limit, -1.01 * limit, f32::NAN, f32::INFINITY] {
            assert_eq!(nack(&mut sim, w), [BoardMsg::Nack(Nack::OutOfRange)], "{w}");
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
            let mut sim = board_with(&co);
            sim.handle(&HostMsg::StartExperiment {
                signal,
                duration_s: 40.0,
            });
            let (p, fault) = run(&mut sim, 3300);
            let what = format!("{signal:?} at u_max {u_max} V, i_max {i_max} A");
            assert_eq!(fault, None, "{what}");
            // The signal itself stays inside the current window: never held at its edge.
            assert!(
                !p.iter().any(|x| x.faults.contains(Faults::CURRENT_LIMIT)),
                "{what}"
            );
            let peak = peak_current(&p);
            assert!(peak < i_limit(&co), "{what}: peak {peak} A");
            // Sized by the smaller of the two, P·u_lim/24 V and 0.35·R·i_max (a multisine's
            // Schroeder phases and slow envelope keep its largest sample near 0.4 of that).
            let u_lim = f64::from(u_max).min(0.95 * 22.2);
            let size = (paper_peak * u_lim / 24.0).min(0.35 * r_i);
            let top = p.iter().map(|x| f64::from(x.u.abs())).fold(0.0, f64::max);
            assert!(
                top <= size + 1e-4 && top > 0.3 * size,
                "{what}: |u| {top} V of {size} V"
            );
        }
    }
}
