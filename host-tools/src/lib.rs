//! `motorid`: the host side of the friction-aware BLDC toolkit.
//!
//! | module | what it is |
//! |---|---|
//! | [`log`] | motor logs (CSV): read with `--map`/`--plant`, write atomically |
//! | [`atomic`] | atomic output files (write to a temporary file, then rename) |
//! | [`cmd`] | one file per `motorid` subcommand: its `--help` text and its `run` |
//! | [`effect_spec`] | effect specs `NAME:key=value,...` with keys, units, defaults |
//! | [`ident`] | identification: fit linear/LuGre/SINDYc models, free-run simulation, fit % |
//! | [`model`] | MODEL.toml: an identified model with units, std errors, provenance |
//! | [`diagnose`] | the model-error workbench: missing effects (F-test), error by region |
//! | [`report`] | self-contained HTML reports with inline SVG plots (compare, diagnose, demo) |
//! | [`emulator`] | the built-in motor emulator: the paper's motor, effects, sensors, signals |
//! | [`validate`] | finite, physical numbers: sample periods, ranges, clap value parsers |
//! | [`input`] | input files: regular files only, size and line-length caps, no file twice |
//! | [`warnings`] | `warning:` lines about the inputs, held until the inputs are checked |
pub mod atomic;
pub mod board;
pub mod closed_loop;
pub mod cmd;
pub mod diagnose;
pub mod effect_spec;
pub mod effects;
pub mod emulator;
pub mod ident;
pub mod input;
pub mod log;
pub mod matlab;
pub mod model;
pub mod numerics;
pub mod report;
pub mod scales;
pub mod validate;
pub mod warnings;
pub mod workflow;
