//! `warning:` lines about the inputs, held until the inputs are all read and checked.
//!
//! A command that fails on its input prints one `error:` line and nothing else, so the
//! warnings about its inputs wait here: a command calls [`flush`] once its inputs are read and
//! checked (before a long computation, so that they are seen early), `main` calls [`flush`]
//! when the command succeeds and [`discard`] when it fails before that.
use std::sync::Mutex;

static HELD: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Hold a warning (without its `warning: ` prefix) until [`flush`].
pub fn hold(msg: String) {
    if let Ok(mut held) = HELD.lock() {
        held.push(msg);
    }
}

/// Print every held warning on stderr as a `warning:` line, in the order they came.
pub fn flush() {
    let held = HELD.lock().map(|mut h| std::mem::take(&mut *h));
    for w in held.unwrap_or_default() {
        eprintln!("warning: {}", crate::log::escape_controls(&w));
    }
}

/// Drop every held warning (the command failed on its input; its `error:` line says why).
pub fn discard() {
    if let Ok(mut held) = HELD.lock() {
        held.clear();
    }
}
