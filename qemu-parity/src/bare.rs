//! Bare-metal start-up and output for QEMU `mps2-an386`: vector table, reset (FPU on, RAM
//! initialised), semihosting output and exit. No cortex-m-rt: this crate links with its own
//! `mps2-an386.x` (see build.rs).
use core::fmt::Write;
use cortex_m_semihosting::{debug, hio};
use qemu_parity::{run_trace, Observer, Trace};

/// Vector table after the initial stack pointer: reset, then the 14 system exceptions.
#[link_section = ".vector_table.qp"]
#[no_mangle]
#[used]
pub static QP_VECTORS: [unsafe extern "C" fn() -> !; 15] = [
    qp_reset, qp_fault, qp_fault, qp_fault, qp_fault, qp_fault, qp_fault, qp_fault, qp_fault,
    qp_fault, qp_fault, qp_fault, qp_fault, qp_fault, qp_fault,
];

extern "C" {
    static mut __qp_sdata: u32;
    static mut __qp_edata: u32;
    static __qp_sidata: u32;
    static mut __qp_sbss: u32;
    static mut __qp_ebss: u32;
}

/// Reset: enable the FPU (CPACR CP10/CP11 full access), copy `.data`, zero `.bss`, run.
///
/// # Safety
/// Entered by the CPU out of reset only.
#[no_mangle]
pub unsafe extern "C" fn qp_reset() -> ! {
    const CPACR: *mut u32 = 0xE000_ED88 as *mut u32;
    core::ptr::write_volatile(CPACR, core::ptr::read_volatile(CPACR) | (0xF << 20));
    core::arch::asm!("dsb", "isb");
    let mut src = core::ptr::addr_of!(__qp_sidata);
    let mut dst = core::ptr::addr_of_mut!(__qp_sdata);
    while dst < core::ptr::addr_of_mut!(__qp_edata) {
        core::ptr::write_volatile(dst, core::ptr::read(src));
        dst = dst.add(1);
        src = src.add(1);
    }
    let mut b = core::ptr::addr_of_mut!(__qp_sbss);
    while b < core::ptr::addr_of_mut!(__qp_ebss) {
        core::ptr::write_volatile(b, 0);
        b = b.add(1);
    }
    main()
}

/// Any fault: report and exit QEMU with a failure status.
///
/// # Safety
/// Entered by the CPU on an exception only.
#[no_mangle]
pub unsafe extern "C" fn qp_fault() -> ! {
    if let Ok(mut out) = hio::hstderr() {
        let _ = out.write_str("error: CPU fault on the emulated Cortex-M4\n");
    }
    loop {
        debug::exit(debug::EXIT_FAILURE);
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if let Ok(mut out) = hio::hstderr() {
        let _ = writeln!(out, "error: panic on the emulated Cortex-M4: {info}");
    }
    loop {
        debug::exit(debug::EXIT_FAILURE);
    }
}

// Step markers: empty, never inlined, each with a distinct body so that no pass merges them.
// The instruction counter (`qemu-parity count`) looks for their addresses in QEMU's exec log.
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_begin_none() {
    unsafe { core::arch::asm!("mov {0}, #1", out(reg) _, options(nomem, nostack)) }
}
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_begin_lugre() {
    unsafe { core::arch::asm!("mov {0}, #2", out(reg) _, options(nomem, nostack)) }
}
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_begin_sindyc() {
    unsafe { core::arch::asm!("mov {0}, #3", out(reg) _, options(nomem, nostack)) }
}
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_begin_sindyc_a() {
    unsafe { core::arch::asm!("mov {0}, #5", out(reg) _, options(nomem, nostack)) }
}
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_begin_lugre_table() {
    unsafe { core::arch::asm!("mov {0}, #6", out(reg) _, options(nomem, nostack)) }
}
#[no_mangle]
#[inline(never)]
pub extern "C" fn qp_end() {
    unsafe { core::arch::asm!("mov {0}, #4", out(reg) _, options(nomem, nostack)) }
}

/// A line buffer: one semihosting call per line instead of one per formatted piece.
struct Line {
    buf: [u8; 160],
    len: usize,
}

impl Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let b = s.as_bytes();
        let end = self.len + b.len();
        if end > self.buf.len() {
            return Err(core::fmt::Error);
        }
        self.buf[self.len..end].copy_from_slice(b);
        self.len = end;
        Ok(())
    }
}

fn main() -> ! {
    let mut out = match hio::hstdout() {
        Ok(o) => o,
        Err(()) => loop {
            debug::exit(debug::EXIT_FAILURE);
        },
    };
    let mut line = Line {
        buf: [0; 160],
        len: 0,
    };
    let mut flush = |line: &mut Line| {
        let _ = out.write_all(&line.buf[..line.len]);
        line.len = 0;
    };
    let trace = match Trace::parse(crate::TRACE) {
        Ok(t) => t,
        Err(e) => panic!("embedded trace unreadable: {e:?}"),
    };
    let addr = |f: extern "C" fn()| (f as usize) & !1;
    let _ = writeln!(
        line,
        "markers {:#x} {:#x} {:#x} {:#x} {:#x} {:#x}",
        addr(qp_begin_none),
        addr(qp_begin_lugre),
        addr(qp_begin_sindyc),
        addr(qp_begin_sindyc_a),
        addr(qp_begin_lugre_table),
        addr(qp_end)
    );
    flush(&mut line);
    let mut line2 = Line {
        buf: [0; 160],
        len: 0,
    };
    let done = run_trace(
        &trace,
        &crate::BLOBS,
        |obs, k, outs| {
            let _ = write!(line2, "out {} {}", obs.name(), k);
            for v in outs {
                let _ = write!(line2, " {v:08x}");
            }
            let _ = writeln!(line2);
            flush(&mut line2);
        },
        |obs, begin| match (obs, begin) {
            (Observer::None, true) => qp_begin_none(),
            (Observer::Lugre, true) => qp_begin_lugre(),
            (Observer::Sindyc, true) => qp_begin_sindyc(),
            (Observer::SindycSignalA, true) => qp_begin_sindyc_a(),
            (Observer::LugreTable, true) => qp_begin_lugre_table(),
            (_, false) => qp_end(),
        },
    );
    if let Err(e) = done {
        panic!("embedded coefficient blob unreadable: {e}");
    }
    let _ = writeln!(line, "done {}", trace.steps);
    flush(&mut line);
    loop {
        debug::exit(debug::EXIT_SUCCESS);
    }
}
