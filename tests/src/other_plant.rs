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
}

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

    /// Derivative of the state [θ, ω, I, θ2, ω2] at time `t` with voltage `v`.
    fn deriv(&self, t: f64, x: &[f64; 5], v: f64) -> [f64; 5] {
        let [_, w, i, _, w2] = *x;
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
            _ => 0.0,
        };
        let drive = self.kt_at(i) * i - load;
        let friction = if w.abs() < self.v_eps {
            (drive - coupling + self.j * w / 1e-3).clamp(-fc, fc)
        } else {
            let (dfc, db) = match self.extra {
                Extra::Directional { dfc, db } => (dfc, db),
                _ => (0.0, 0.0),
            };
            (fc + dfc * w.signum()) * w.signum() + (self.b + db * w.signum()) * w
        };
        [
            w,
            (drive - friction - coupling) / self.j,
            (v - self.r * i - self.kt * w) / self.l,
            w2,
            load_acc,
        ]
    }

    /// Run the plant on `u` (volts held over each period `ts`) and sample it like the board.
    pub fn run(&self, u: &[f64], ts: f64, seed: u64) -> MotorLog {
        let sub = 240; // 50 µs steps: RK4 stable for L/R ≈ 1.3 ms and an 80 Hz contact.
        let h = ts / sub as f64;
        let mut x = [0.0f64; 5];
        let mut rng = Lcg(seed.wrapping_mul(6364136223846793005).wrapping_add(1));
        let mut log = MotorLog {
            source: PathBuf::from("other_plant.csv"),
            meta: BTreeMap::new(),
            ..MotorLog::default()
        };
        let mut i_meas = Vec::with_capacity(u.len());
        for (k, &v) in u.iter().enumerate() {
            let t = k as f64 * ts;
            log.t.push(t);
            log.u.push(v);
            log.theta.push((x[0] / self.hall).floor() * self.hall);
            i_meas.push(x[2] + self.current_noise * rng.gauss());
            for s in 0..sub {
                let tt = t + s as f64 * h;
                let k1 = self.deriv(tt, &x, v);
                let k2 = self.deriv(tt + h / 2.0, &add(&x, &k1, h / 2.0), v);
                let k3 = self.deriv(tt + h / 2.0, &add(&x, &k2, h / 2.0), v);
                let k4 = self.deriv(tt + h, &add(&x, &k3, h), v);
                for j in 0..5 {
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
        log
    }
}

fn add(x: &[f64; 5], d: &[f64; 5], h: f64) -> [f64; 5] {
    let mut y = *x;
    for j in 0..5 {
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
