//! A motor written apart from `motorid`'s emulator, for testing diagnosis on data our own
//! equations did not make: a classical RK4 integrator on a fine grid (not the emulator's exact
//! and implicit updates), a Karnopp stick-slip friction law (not LuGre), and physics the effect list has in
//! other forms or not at all: a second inertia on a spring-damper coupling, a gap between motor
//! and load, a torque constant that falls along a tabulated curve, Coulomb friction that grows
//! over the run. Sampled like the board: Hall-quantised angle, noisy current, held voltage.
use motorid::log::MotorLog;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Physics of the plant beyond a rigid motor with Coulomb and viscous friction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Extra {
    None,
    /// Load inertia `j2` on a spring `k` [N·m/rad] and damper `c` [N·m·s/rad].
    Coupling {
        j2: f64,
        k: f64,
        c: f64,
    },
    /// Load inertia `j2` engaged across a total gap `gap` [rad] by a stiff contact.
    Gap {
        j2: f64,
        gap: f64,
    },
    /// Torque constant falling with |I| along a tabulated curve (fraction of K_t at 0, 10,
    /// 20, 30, 40 A, linear in between).
    FallingKt,
    /// Coulomb friction growing linearly in time by `per_minute` of itself.
    CreepingCoulomb {
        per_minute: f64,
    },
    /// Friction that differs by direction: Coulomb `fc + dfc` forward and `fc − dfc`
    /// backward, viscous `b + db` forward and `b − db` backward.
    Directional {
        dfc: f64,
        db: f64,
    },
    /// A load torque that rises linearly over each revolution and drops back at θ = 0 (a
    /// cam or a spring that releases once per turn): `amp·((θ mod 2π)/π − 1)` [N·m].
    SawtoothLoad {
        amp: f64,
    },
    /// Cogging of a slotted stator: the first two harmonics of the slot count `slots`,
    /// `a1·sin(N·θ + p1) + a2·sin(2N·θ + p2)` [N·m], each with its own phase.
    SlotCogging {
        slots: u16,
        a1: f64,
        p1: f64,
        a2: f64,
        p2: f64,
    },
    /// Inverter dead time: the bridge loses `vd` [V] against the current's direction, its
    /// sign passing linearly through zero across the ripple band `±band` [A].
    DeadTime {
        vd: f64,
        band: f64,
    },
    /// Winding heating: temperature rise ΔT [K] over ambient with `C·dΔT/dt = I²·R(ΔT) −
    /// ΔT/r_th` (heat capacity `c_th` [J/K], thermal resistance `r_th` [K/W]) and copper's
    /// `R(ΔT) = R·(1 + 0.00393·ΔT)`. The winding starts at ambient.
    Heating {
        r_th: f64,
        c_th: f64,
    },
    /// The current sensor reads `i0` [A] more than flows.
    SensorOffset {
        i0: f64,
    },
    /// A constant load torque `t0` [N·m] against positive rotation.
    ConstantLoad {
        t0: f64,
    },
    /// An unbalanced load under gravity, once per revolution, with a second harmonic:
    /// `a1·sin(θ + p1) + a2·sin(2θ + p2)` [N·m].
    Unbalance {
        a1: f64,
        p1: f64,
        a2: f64,
        p2: f64,
    },
    /// A gear between the rotor and a load of reflected inertia `j_load` [kg·m²] (part of
    /// the plant's `j`) that also carries half of the plant's Coulomb and viscous friction;
    /// the tooth contact loses `mu·|T|` of the torque `T` it transmits, against the motion.
    GearFriction {
        mu: f64,
        j_load: f64,
    },
    /// Static friction above Coulomb falling with speed on a Lorentzian curve,
    /// `fs/(1 + (ω/vs)²)` [N·m] against the motion; at rest the contact holds up to
    /// `fc + fs`.
    Breakaway {
        fs: f64,
        vs: f64,
    },
}

/// Relative rise of copper's resistance per kelvin (at 20 °C).
const COPPER_ALPHA: f64 = 0.00393;

/// The plant's constants (SI).
#[derive(Debug, Clone, Copy)]
pub struct OtherPlant {
    pub r: f64,
    pub l: f64,
    pub kt: f64,
    pub j: f64,
    pub fc: f64,
    pub b: f64,
    /// Half-width of the Karnopp stick band [rad/s].
    pub v_eps: f64,
    pub extra: Extra,
    pub current_noise: f64,
    pub hall: f64,
}

impl OtherPlant {
    /// Constants near the reference paper's motor (so the same excitation suits it).
    pub fn new(extra: Extra) -> OtherPlant {
        OtherPlant {
            r: 0.22,
            l: 0.28e-3,
            kt: 0.0712,
            j: 3.1e-4,
            fc: 0.085,
            b: 1.5e-3,
            v_eps: 0.01,
            extra,
            current_noise: 0.05,
            hall: 2.0 * std::f64::consts::PI / 66.0,
        }
    }

    fn kt_at(&self, i: f64) -> f64 {
        match self.extra {
            Extra::FallingKt => {
                const TABLE: [f64; 5] = [1.0, 0.97, 0.88, 0.76, 0.66];
                let x = (i.abs() / 10.0).min(3.999);
                let j = x.floor() as usize;
                let w = x - j as f64;
                self.kt * (TABLE[j] * (1.0 - w) + TABLE[j + 1] * w)
            }
            _ => self.kt,
        }
    }

    /// The torque constant [N·m/A] at current `i` [A]: K_t, or on a [`Extra::FallingKt`]
    /// plant its tabulated value.
    pub fn torque_constant_at(&self, i: f64) -> f64 {
        self.kt_at(i)
    }

    /// Derivative of the state [θ, ω, I, θ2, ω2, ΔT] at time `t` with voltage `v`.
    fn deriv(&self, t: f64, x: &[f64; 6], v: f64) -> [f64; 6] {
        let [_, w, i, _, w2, heat] = *x;
        let fc = match self.extra {
            Extra::CreepingCoulomb { per_minute } => self.fc * (1.0 + per_minute * t / 60.0),
            _ => self.fc,
        };
        let (coupling, load_acc) = match self.extra {
            Extra::Coupling { j2, k, c } => {
                let tq = k * (x[0] - x[3]) + c * (w - w2);
                (tq, tq / j2)
            }
            Extra::Gap { j2, gap } => {
                let d = x[0] - x[3];
                let half = gap / 2.0;
                let pen = if d > half {
                    d - half
                } else if d < -half {
                    d + half
                } else {
                    0.0
                };
                // A stiff, well-damped contact (about 80 Hz against the load).
                let tq = if pen != 0.0 {
                    let k = j2 * (2.0 * std::f64::consts::PI * 80.0f64).powi(2);
                    k * pen + 2.0 * 0.7 * (k * j2).sqrt() * (w - w2)
                } else {
                    0.0
                };
                (tq, tq / j2 - 0.002 * w2.signum() / j2)
            }
            _ => (0.0, 0.0),
        };
        // Karnopp stick-slip: inside a small velocity band the friction holds the rotor (it
        // balances every other torque and damps the residual speed in about a millisecond)
        // as long as that takes no more than the Coulomb level; outside, Coulomb + viscous.
        let load = match self.extra {
            Extra::SawtoothLoad { amp } => {
                let tau = 2.0 * std::f64::consts::PI;
                amp * (x[0].rem_euclid(tau) / std::f64::consts::PI - 1.0)
            }
            Extra::SlotCogging {
                slots,
                a1,
                p1,
                a2,
                p2,
            } => {
                let n = f64::from(slots);
                a1 * (n * x[0] + p1).sin() + a2 * (2.0 * n * x[0] + p2).sin()
            }
            Extra::ConstantLoad { t0 } => t0,
            Extra::Unbalance { a1, p1, a2, p2 } => {
                a1 * (x[0] + p1).sin() + a2 * (2.0 * x[0] + p2).sin()
            }
            _ => 0.0,
        };
        let drive = self.kt_at(i) * i - load;
        // What the contact can hold at rest: more than Coulomb where static friction
        // exceeds it, or where the gear's teeth are pressed by the drive.
        let hold = match self.extra {
            Extra::Breakaway { fs, .. } => fc + fs,
            Extra::GearFriction { mu, .. } => fc + mu * drive.abs(),
            _ => fc,
        };
        let friction = if w.abs() < self.v_eps {
            (drive - coupling + self.j * w / 1e-3).clamp(-hold, hold)
        } else {
            let (dfc, db) = match self.extra {
                Extra::Directional { dfc, db } => (dfc, db),
                _ => (0.0, 0.0),
            };
            let sliding = (fc + dfc * w.signum()) * w.signum() + (self.b + db * w.signum()) * w;
            match self.extra {
                Extra::Breakaway { fs, vs } => sliding + fs / (1.0 + (w / vs).powi(2)) * w.signum(),
                Extra::GearFriction { mu, j_load } => {
                    sliding
                        + mu * self.gear_torque(drive, sliding, j_load, mu, w).abs() * w.signum()
                }
                _ => sliding,
            }
        };
        let (r, v_loss) = match self.extra {
            Extra::Heating { .. } => (self.r * (1.0 + COPPER_ALPHA * heat), 0.0),
            Extra::DeadTime { vd, band } => (self.r, vd * (i / band).clamp(-1.0, 1.0)),
            _ => (self.r, 0.0),
        };
        let heating = match self.extra {
            Extra::Heating { r_th, c_th } => (i * i * r - heat / r_th) / c_th,
            _ => 0.0,
        };
        [
            w,
            (drive - friction - coupling) / self.j,
            (v - v_loss - r * i - self.kt * w) / self.l,
            w2,
            load_acc,
            heating,
        ]
    }

    /// Torque the gear transmits to its load while sliding: the rotor (inertia `j − j_load`)
    /// and the load (`j_load`) share one acceleration; the rotor takes the drive less half
    /// the plant's friction `sliding`, the load the other half and the tooth loss
    /// `mu·|T|·sgn(ω)`. Solved for `T`, whose sign is that of the numerator (the
    /// denominator stays positive for `mu < 1`).
    fn gear_torque(&self, drive: f64, sliding: f64, j_load: f64, mu: f64, w: f64) -> f64 {
        let q = j_load / (self.j - j_load);
        let num = q * (drive - 0.5 * sliding) + 0.5 * sliding;
        num / (1.0 + q - mu * num.signum() * w.signum())
    }

    /// Run the plant on `u` (volts held over each period `ts`) and sample it like the board.
    pub fn run(&self, u: &[f64], ts: f64, seed: u64) -> MotorLog {
        self.run_with_velocity(u, ts, seed, 0.0).0
    }

    /// [`OtherPlant::run`] from the rotor (and load) angle `theta0` [rad], with the rotor's
    /// true velocity at each sample [rad/s] (which the log, like the board's, does not
    /// carry): what a model's free run is scored against.
    pub fn run_with_velocity(
        &self,
        u: &[f64],
        ts: f64,
        seed: u64,
        theta0: f64,
    ) -> (MotorLog, Vec<f64>) {
        let sub = 240; // 50 µs steps: RK4 stable for L/R ≈ 1.3 ms and an 80 Hz contact.
        let h = ts / sub as f64;
        let mut x = [theta0, 0.0, 0.0, theta0, 0.0, 0.0];
        let mut rng = Lcg(seed.wrapping_mul(6364136223846793005).wrapping_add(1));
        let mut log = MotorLog {
            source: PathBuf::from("other_plant.csv"),
            meta: BTreeMap::new(),
            ..MotorLog::default()
        };
        let mut i_meas = Vec::with_capacity(u.len());
        let mut omega = Vec::with_capacity(u.len());
        for (k, &v) in u.iter().enumerate() {
            let t = k as f64 * ts;
            log.t.push(t);
            log.u.push(v);
            log.theta.push((x[0] / self.hall).floor() * self.hall);
            let mut read = x[2] + self.current_noise * rng.gauss();
            if let Extra::SensorOffset { i0 } = self.extra {
                read += i0;
            }
            i_meas.push(read);
            omega.push(x[1]);
            for s in 0..sub {
                let tt = t + s as f64 * h;
                let k1 = self.deriv(tt, &x, v);
                let k2 = self.deriv(tt + h / 2.0, &add(&x, &k1, h / 2.0), v);
                let k3 = self.deriv(tt + h / 2.0, &add(&x, &k2, h / 2.0), v);
                let k4 = self.deriv(tt + h, &add(&x, &k3, h), v);
                for j in 0..6 {
                    x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                }
                if !matches!(self.extra, Extra::Coupling { .. } | Extra::Gap { .. }) {
                    x[3] = x[0];
                    x[4] = x[1];
                }
            }
        }
        log.i = Some(i_meas);
        log.meta.insert("sample_period".into(), format!("{ts}"));
        log.meta
            .insert("hall_resolution_rad".into(), format!("{}", self.hall));
        (log, omega)
    }
}

fn add(x: &[f64; 6], d: &[f64; 6], h: f64) -> [f64; 6] {
    let mut y = *x;
    for j in 0..6 {
        y[j] += h * d[j];
    }
    y
}

/// A small generator of its own (Box–Muller over a 64-bit LCG), independent of `rand`.
struct Lcg(u64);

impl Lcg {
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}

/// Elements of a [`PreslidingPlant`]'s friction.
pub const PRESLIDING_ELEMENTS: usize = 4;

/// A rigid motor whose friction deflects before it slides, written as a Maxwell-slip model:
/// [`PRESLIDING_ELEMENTS`] elasto-plastic elements in parallel, element `j` a spring that
/// carries an equal share of the Coulomb level `fc` once deflected by `(j + 1)/N` of
/// `breakaway` [rad] and slips beyond, plus viscous friction. Unlike LuGre's single bristle
/// with a rate law, each element is a play operator: the friction grows along a piecewise
/// linear, ever softer curve after each reversal and reaches `fc` once the rotor has turned
/// `breakaway` since; at rest the springs hold the rotor (no stick band), and the slips of
/// the softer elements damp its small motions. The motor, its sampling and its noise are
/// those of [`OtherPlant`] (its `extra` is not used).
#[derive(Debug, Clone, Copy)]
pub struct PreslidingPlant {
    pub base: OtherPlant,
    /// Rotor travel after a reversal over which the friction builds up to `fc` [rad].
    pub breakaway: f64,
}

impl PreslidingPlant {
    /// Slip deflection [rad] and stiffness [N·m/rad] of element `j`.
    fn element(&self, j: usize) -> (f64, f64) {
        let n = PRESLIDING_ELEMENTS as f64;
        let d = self.breakaway * (j + 1) as f64 / n;
        (d, self.base.fc / n / d)
    }

    /// Friction torque [N·m] with the elements at `z`, the rotor `dth` [rad] further on (in
    /// one direction) and turning at `w` [rad/s].
    fn friction(&self, z: &[f64; PRESLIDING_ELEMENTS], dth: f64, w: f64) -> f64 {
        let springs: f64 = (0..PRESLIDING_ELEMENTS)
            .map(|j| {
                let (d, k) = self.element(j);
                k * (z[j] + dth).clamp(-d, d)
            })
            .sum();
        springs + self.base.b * w
    }

    /// Run the plant on `u` (volts held over each period `ts`) from rest with the elements
    /// relaxed, and sample it like the board (as [`OtherPlant::run`]).
    pub fn run(&self, u: &[f64], ts: f64, seed: u64) -> MotorLog {
        let p = &self.base;
        // 50 µs steps, as the other plant; within a step the elements' deflections follow
        // the rotor exactly while it does not reverse.
        let sub = 240;
        let h = ts / sub as f64;
        let mut z = [0.0; PRESLIDING_ELEMENTS];
        // θ, ω, I.
        let mut x = [0.0f64; 3];
        let deriv = |z: &[f64; PRESLIDING_ELEMENTS], x0: f64, y: &[f64; 3], v: f64| {
            let [th, w, i] = *y;
            [
                w,
                (p.kt * i - self.friction(z, th - x0, w)) / p.j,
                (v - p.r * i - p.kt * w) / p.l,
            ]
        };
        let step = |y: &[f64; 3], d: &[f64; 3], s: f64| {
            [y[0] + s * d[0], y[1] + s * d[1], y[2] + s * d[2]]
        };
        let mut rng = Lcg(seed.wrapping_mul(6364136223846793005).wrapping_add(1));
        let mut log = MotorLog {
            source: PathBuf::from("presliding_plant.csv"),
            meta: BTreeMap::new(),
            ..MotorLog::default()
        };
        let mut i_meas = Vec::with_capacity(u.len());
        for (k, &v) in u.iter().enumerate() {
            log.t.push(k as f64 * ts);
            log.u.push(v);
            log.theta.push((x[0] / p.hall).floor() * p.hall);
            i_meas.push(x[2] + p.current_noise * rng.gauss());
            for _ in 0..sub {
                let x0 = x[0];
                let k1 = deriv(&z, x0, &x, v);
                let k2 = deriv(&z, x0, &step(&x, &k1, h / 2.0), v);
                let k3 = deriv(&z, x0, &step(&x, &k2, h / 2.0), v);
                let k4 = deriv(&z, x0, &step(&x, &k3, h), v);
                for j in 0..3 {
                    x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                }
                for (j, zj) in z.iter_mut().enumerate() {
                    let (d, _) = self.element(j);
                    *zj = (*zj + x[0] - x0).clamp(-d, d);
                }
            }
        }
        log.i = Some(i_meas);
        log.meta.insert("sample_period".into(), format!("{ts}"));
        log.meta
            .insert("hall_resolution_rad".into(), format!("{}", p.hall));
        log
    }
}
