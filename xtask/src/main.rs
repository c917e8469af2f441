//! `cargo xtask`: regenerate the result pages of `docs/` (the paper's fit table on the
//! emulator, the measured data sets) and check a branch's commit messages. Run from the
//! repository root.
use clap::{Parser, Subcommand};
use std::process::ExitCode;
use xtask::cmd;

#[derive(Parser, Debug)]
#[command(
    name = "xtask",
    about = "Regenerate the result tables and figures of docs/, check commit messages (cargo xtask COMMAND)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Regenerate the reference paper's fit table on emulated data.
    PaperTable(cmd::paper_table::Args),
    /// Fit and diagnose the measured data sets in ../shared/data (EMPS, screw drives, DC motors).
    RealData(cmd::real_data::Args),
    /// Check a branch's commit messages: subject of at most 72 characters, then a body.
    Commits(cmd::commits::Args),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    let result = match cli.command {
        Command::PaperTable(a) => cmd::paper_table::run(a),
        Command::RealData(a) => cmd::real_data::run(a),
        Command::Commits(a) => cmd::commits::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}
