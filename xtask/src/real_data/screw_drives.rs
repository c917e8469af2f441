//! The TRO2021 screw drives (Mablekos-Alexiou, da Cruz, Bergeles, IEEE T-RO 2021): three
//! screw-based drives run at constant speed set-points by a Maxon EPOS controller. Each
//! set-point gives one steady-state (velocity, motor torque) point of the static friction
//! curve; [`super::static_curve`] fits and tests the curve.
use super::static_curve::{self, Selection};
use super::table_csv::{mean_sd, plateaus, Table};
use anyhow::Result;
use std::path::{Path, PathBuf};

/// Fraction of each set-point's samples skipped as the start-up transient (the first 10 %).
pub const SKIP_FRACTION: f64 = 0.1;

/// One drive: its name and the authors' Stribeck velocity (`strbVelocity` in `sd_1dof.m`).
pub const DRIVES: [(usize, &str, f64); 3] = [
    (1, "lead screw", 6.4),
    (2, "anti-backlash lead screw", 0.0),
    (3, "worm drive 60:1", 0.688),
];

/// A steady-state point: mean velocity [rad/s] and torque [N·m] at one set-point, with the
/// standard deviation of the torque samples.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    pub setpoint_rpm: f64,
    pub v: f64,
    pub tau: f64,
    pub tau_sd: f64,
    pub samples: usize,
}

/// The file of drive `k` in the data directory.
pub fn path(data: &Path, k: usize) -> PathBuf {
    data.join("TRO2021_screw_drives")
        .join(format!("TRO2021_driveNo{k}_steady_state.csv"))
}

/// Read the stacked steady-state file and reduce each set-point to one point.
pub fn read_points(path: &Path) -> Result<Vec<Point>> {
    let t = Table::read(path)?;
    let sp = t.col("setpoint_rpm", path)?;
    let v = t.col("velocity_rad_s", path)?;
    let tau = t.col("torque_Nm", path)?;
    let mut out = Vec::new();
    for (set, range) in plateaus(sp, SKIP_FRACTION) {
        let (vm, _) = mean_sd(&v[range.clone()]);
        let (tm, tsd) = mean_sd(&tau[range.clone()]);
        out.push(Point {
            setpoint_rpm: set,
            v: vm,
            tau: tm,
            tau_sd: tsd,
            samples: range.len(),
        });
    }
    Ok(out)
}

/// A drive's analysis.
#[derive(Debug, Clone)]
pub struct DriveResult {
    pub drive: usize,
    pub name: &'static str,
    pub authors_vs: f64,
    pub points: Vec<Point>,
    pub selection: Selection,
    /// Stribeck tested per direction (v > 0, v < 0).
    pub one_sided: Vec<static_curve::OneSided>,
}

/// Fit and test the static curve of drive `k`.
pub fn analyse(data: &Path, k: usize) -> Result<DriveResult> {
    let (_, name, authors_vs) = DRIVES[k - 1];
    let points = read_points(&path(data, k))?;
    let v: Vec<f64> = points.iter().map(|p| p.v).collect();
    let tau: Vec<f64> = points.iter().map(|p| p.tau).collect();
    let selection = static_curve::select(&v, &tau, static_curve::ALPHA)?;
    let one_sided = static_curve::one_sided_stribeck(&v, &tau);
    Ok(DriveResult {
        one_sided,
        drive: k,
        name,
        authors_vs,
        points,
        selection,
    })
}
