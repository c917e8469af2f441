//! The board side of the toolkit: coefficients for the firmware, the emulated board behind a
//! pseudo-terminal, and the serial link client that talks to either.
//!
//! | module | what it is |
//! |---|---|
//! | [`coeffs`] | MODEL.toml → coefficient blob → control-step configuration |
//! | [`rig`] | the emulated board: control step (f32) + emulated motor, 12 ms at a time |
pub mod coeffs;
pub mod flash;
pub mod link;
pub mod pty;
pub mod rig;
pub mod sim;
