//! The board side of the toolkit: coefficients for the firmware, the emulated board behind a
//! pseudo-terminal, and the serial link client that talks to either.
//!
//! | module | what it is |
//! |---|---|
//! | [`coeffs`] | MODEL.toml → [`control::blob::Coefficients`] → blob bytes; blob files checked |
//! | [`coeff_text`] | the coefficients as JSON and as a C header, for firmware not in Rust |
//! | [`step_rig`] | the firmware's control step (f32) alone on the emulated motor, 12 ms at a time |
//! | [`emulated_board`] | the whole emulated board: `control::board` (the firmware's logic) on [`hw`] |
//! | [`hw`] | the emulated hardware: motor, six-step bridge, Hall inputs, wiring |
//! | [`emulated_flash`] | the emulated coefficient flash (RAM or file) for `control::slots` |
//! | [`pace`] | when the emulated board runs its next period, on the host's clock |
//! | [`pty`] | a raw pseudo-terminal whose slave device clients open as a serial port |
//! | [`link`] | the serial link client: identify, upload, experiments, with retries |
pub mod coeff_text;
pub mod coeffs;
pub mod emulated_board;
pub mod emulated_flash;
pub mod hw;
pub mod link;
pub mod pace;
pub mod pty;
pub mod step_rig;
