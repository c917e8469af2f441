//! Link setup for the bare-metal build (QEMU `mps2-an386`), distinct from the board's.
//!
//! The workspace's `.cargo/config.toml` passes `-Tlink.x -Tdefmt.x` to every
//! `thumbv7em-none-eabihf` link (the firmware's cortex-m-rt and defmt scripts). This crate
//! uses neither: it ships its own `link.x` (the mps2-an386 memory map: code at 0x0000_0000,
//! SRAM at 0x2000_0000) and an empty `defmt.x`, both put in OUT_DIR, so the same flags link
//! it without touching the firmware's setup. Host builds need nothing.
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=mps2-an386.x");
    let target = std::env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumb") {
        return;
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::copy("mps2-an386.x", out.join("link.x")).expect("cannot copy mps2-an386.x");
    std::fs::write(out.join("defmt.x"), "/* this crate does not use defmt */\n")
        .expect("cannot write defmt.x");
    println!("cargo:rustc-link-search={}", out.display());
}
