//! `control`: the one home of every equation that runs on the B-G431B-ESC1 board.
//!
//! `no_std`, no allocation. Equations are generic over [`num_traits::Float`] so that the host
//! (f64 identification and emulation) and the firmware (f32) run the very same code.
//!
//! | module | what it is |
//! |---|---|
//! | [`motor`] | DC-equivalent motor constants (R, L, K_t, K_b, J) |
//! | [`effects`] | the physical effects `motorid` names, as equations |
//! | [`coupling`] | a load behind a spring or a gap, and its implicit step |
//! | [`hall`] | Hall-state decoding, sectors, faults, angle |
//! | [`velocity`] | velocity estimators: moving average (the paper's) and Hall-edge timing |
//! | [`lugre`] | LuGre friction observer with an exact (exponential) update |
//! | [`sindy`] | SINDYc friction model evaluator (sparse named terms) |
//! | [`pi`] | PI speed controller with anti-windup |
//! | [`compensation`] | friction compensation current and voltage |
//! | [`step`] | the 12 ms control step the firmware calls |
//! | [`board`] | the board's logic: commands, modes, limits, faults (firmware and emulator) |
//! | [`commission`] | Hall commissioning: sector table, direction, current sign |
//! | [`excitation`] | open-loop experiment signals, relative to the voltage limit |
//! | [`blob`] | the coefficient blob (postcard + magic + version + CRC32) |
//! | [`frame`] | the serial frame codec (COBS + postcard + CRC) |
//! | [`serde_array`] | fixed-size arrays through serde in a loop (smaller decoder) |
//! | [`slots`] | two-slot flash storage of coefficients, power-cut safe |
//! | [`telemetry`] | loop period, jitter, overruns, cycles per step, lost Hall edges |
//! | [`trig`] | sine and cosine in f32 arithmetic for the board |
#![no_std]
#![forbid(unsafe_code)]

pub mod blob;
pub mod board;
pub mod commission;
pub mod compensation;
pub mod coupling;
pub mod effects;
pub mod excitation;
pub mod frame;
pub mod hall;
pub mod lugre;
pub mod motor;
pub mod pi;
pub mod serde_array;
pub mod sindy;
pub mod slots;
pub mod step;
pub mod telemetry;
pub mod trig;
pub mod velocity;

/// Control period of the paper and of the firmware: 12 ms.
pub const CONTROL_PERIOD_S: f32 = 0.012;
