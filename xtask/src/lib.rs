//! Project automation beside the product: the commands that regenerate the result pages of
//! `docs/` and the code that reads the measured data sets. `motorid` (the package in
//! `host-tools/`) stays the generic tool; everything here depends on it, never the other way.
//!
//! | module | what it is |
//! |---|---|
//! | [`real_data`] | readers and reference analyses of the EMPS benchmark, the TRO2021 screw drives and the OmniRobot DC motors |
//! | [`cmd`] | one file per `cargo xtask` subcommand: its `--help` text and its `run` |
pub mod cmd;
pub mod real_data;
