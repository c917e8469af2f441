//! The OmniRobot DC motors (BrOleg5/research-wheel-slippage): three 24 V DC motors of an
//! omni-wheel robot, speed-controlled through set-point plateaus of ±25…±175 rad/s. Each
//! plateau gives one steady-state point (velocity, motor torque `k_t·i`) and the static curve
//! `T = T_0·sgn ω + b·ω` gives the authors' Coulomb and viscous coefficients.
//!
//! The current column is unsigned; as the authors' pre-processing does, it takes the sign of
//! the velocity.
use super::static_curve::{self, Curve, Selection, Term};
use super::table_csv::{mean_sd, plateaus, Table};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// Torque constant k_t [N·m/A] (`motor_parameters_*.m`).
pub const KT: f64 = 0.0514;
/// Fraction of each plateau skipped as the speed loop's transient (its time constant is
/// 0.153 s ≈ 5 samples; plateaus last ≈ 40 samples, so the first 30 % ≈ 2.4 time constants).
pub const SKIP_FRACTION: f64 = 0.3;
/// The authors' identified (b [N·m·s/rad], T_0 [N·m]) per motor.
pub const REFERENCE: [(f64, f64); 3] = [
    (2.3685e-5, 0.0081312),
    (2.0285e-5, 0.0069712),
    (2.3637e-5, 0.0080917),
];
/// The identification files (speed loop without and with integral action).
pub const FILES: [&str; 2] = [
    "data_for_identification_without_integral.csv",
    "data_for_identification_with_integral.csv",
];

/// A steady-state point of one plateau.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    pub setpoint: f64,
    pub v: f64,
    pub torque: f64,
    pub samples: usize,
}

/// The file `name` in the data directory.
pub fn path(data: &Path, name: &str) -> PathBuf {
    data.join("OmniRobot_DC_motors").join(name)
}

/// Plateau points of motor `m` (1..=3) in one file.
pub fn read_points(path: &Path, m: usize) -> Result<Vec<Point>> {
    let t = Table::read(path)?;
    let sp = t.col(&format!("m{m}setvel_rad_per_s"), path)?;
    let w = t.col(&format!("m{m}vel_rad_per_s"), path)?;
    let cur = t.col(&format!("m{m}cur_A"), path)?;
    let mut out = Vec::new();
    for (set, range) in plateaus(sp, SKIP_FRACTION) {
        // Only samples moving in the commanded direction (dropouts read 0 rad/s).
        let idx: Vec<usize> = range.filter(|&j| w[j] * set > 0.0).collect();
        if set != 0.0 && idx.len() >= 5 {
            let v: Vec<f64> = idx.iter().map(|&j| w[j]).collect();
            let tq: Vec<f64> = idx.iter().map(|&j| KT * cur[j] * w[j].signum()).collect();
            out.push(Point {
                setpoint: set,
                v: mean_sd(&v).0,
                torque: mean_sd(&tq).0,
                samples: idx.len(),
            });
        }
    }
    if out.len() < 4 {
        bail!(
            "{}: motor {m}: only {} speed plateaus found; need at least 4",
            path.display(),
            out.len()
        );
    }
    Ok(out)
}

/// One motor in one file.
#[derive(Debug, Clone)]
pub struct MotorResult {
    pub motor: usize,
    pub file: &'static str,
    pub points: Vec<Point>,
    /// Coulomb + viscous, as the authors' model.
    pub curve: Curve,
    /// What the significance test adds beyond that.
    pub selection: Selection,
}

/// Fit motor `m` in file `file`.
pub fn analyse(data: &Path, file: &'static str, m: usize) -> Result<MotorResult> {
    let points = read_points(&path(data, file), m)?;
    let v: Vec<f64> = points.iter().map(|p| p.v).collect();
    let tq: Vec<f64> = points.iter().map(|p| p.torque).collect();
    let curve = static_curve::fit(&[Term::Coulomb, Term::Viscous], &v, &tq)?;
    let selection = static_curve::select(&v, &tq, static_curve::ALPHA)?;
    Ok(MotorResult {
        motor: m,
        file,
        points,
        curve,
        selection,
    })
}
