//! `motorid`: the host side of the friction-aware BLDC toolkit.
//!
//! | module | what it is |
//! |---|---|
//! | [`log`] | motor logs (the contract's CSV): read with `--map`/`--plant`, write atomically |
//! | [`atomic`] | atomic output files (write to a temporary file, then rename) |
//! | [`cmd`] | one file per `motorid` subcommand: its `--help` text and its `run` |
//! | [`effect_spec`] | effect specs `NAME:key=value,...` with keys, units, defaults |
pub mod atomic;
pub mod cmd;
pub mod effect_spec;
pub mod log;
