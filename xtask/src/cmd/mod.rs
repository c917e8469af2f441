//! One file per `cargo xtask` subcommand. Each has `Args` (its `--help`) and `run`.
pub mod commits;
pub mod paper_table;
pub mod real_data;
