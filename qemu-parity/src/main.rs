//! `qemu-parity`: the board logic and its control step over a recorded input trace, on two
//! machines.
//!
//! * Built for `thumbv7em-none-eabihf`, it is a bare-metal program for QEMU's `mps2-an386`
//!   (Cortex-M4F): it runs [`qemu_parity::run_trace`] on the embedded trace and prints every
//!   output as raw `f32` bits through semihosting, then exits QEMU.
//! * Built for the host, it runs the same code on the same trace and compares (`compare`), or
//!   counts instructions per period of the board logic from QEMU's `-d exec` log (`count`).
//!
//! Printed lines (both runs): `markers <begin_none> <begin_lugre> <begin_sindyc>
//! <begin_sindyc_a> <begin_lugre_table> <end>`
//! (code addresses of the step markers), `out <observer> <step> <word>...` (the step's
//! outputs v_cmd, theta, omega, friction, v_comp, z as f32 bits, then the fault bits),
//! `done <steps>`.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

/// The recorded input trace (see `qemu_parity` for the format).
static TRACE: &[u8] = include_bytes!("../trace/closed_loop.qpt");
/// The LuGre model's coefficient blob (`motorid export`).
static LUGRE: &[u8] = include_bytes!("../trace/lugre.bin");
/// The SINDYc model's coefficient blob (`motorid export`).
static SINDYC: &[u8] = include_bytes!("../trace/sindyc.bin");
/// The LuGre model with all eight effect slots used (`motorid export`).
static LUGRE_TABLE: &[u8] = include_bytes!("../trace/lugre-table.bin");

/// The configurations' blobs.
static BLOBS: qemu_parity::Blobs<'static> = qemu_parity::Blobs {
    lugre: LUGRE,
    sindyc: SINDYC,
    lugre_table: LUGRE_TABLE,
};

#[cfg(target_os = "none")]
mod bare;

#[cfg(not(target_os = "none"))]
mod host;

#[cfg(not(target_os = "none"))]
fn main() -> std::process::ExitCode {
    host::main(TRACE, &BLOBS)
}
