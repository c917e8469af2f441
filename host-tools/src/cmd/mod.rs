//! One file per `motorid` subcommand. Each has `Args` (its `--help`) and `run`.
pub mod board;
pub mod clear_fault;
pub mod commission;
pub mod compare;
pub mod demo;
pub mod diagnose;
pub mod emulate;
pub mod export;
pub mod fit;
pub mod flash;
pub mod inspect;
pub mod record;
pub mod simulate;
pub mod upload;
