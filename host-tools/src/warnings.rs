//! `warning:` lines about the inputs, held until the inputs are all read and checked.
//!
//! A command that fails on its input prints one `error:` line and nothing else, so the
//! warnings about its inputs wait here: a command calls [`flush`] once its inputs are read and
//! checked (before a long computation, so that they are seen early), `main` calls [`flush`]
//! when the command succeeds and [`discard`] when it fails before that.
use std::sync::Mutex;

static HELD: Mutex<Vec<(String, usize)>> = Mutex::new(Vec::new());

/// Hold a warning (without its `warning: ` prefix) until [`flush`].
pub fn hold(msg: String) {
    if let Ok(mut held) = HELD.lock() {
        // A warning repeated (a board reporting each damaged frame) is shown once, with
        // how many times it came.
        match held.iter_mut().find(|(m, _)| *m == msg) {
            Some((_, n)) => *n += 1,
            None => held.push((msg, 1)),
        }
    }
}

/// Print every held warning on stderr as a `warning:` line, in the order they came.
pub fn flush() {
    let held = HELD.lock().map(|mut h| std::mem::take(&mut *h));
    for (w, n) in held.unwrap_or_default() {
        let times = if n > 1 {
            format!(" ({n} times)")
        } else {
            String::new()
        };
        eprintln!("warning: {}{times}", crate::log::escape_controls(&w));
    }
}

/// Drop every held warning (the command failed on its input; its `error:` line says why).
pub fn discard() {
    if let Ok(mut held) = HELD.lock() {
        held.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_repeated_warning_is_held_once_with_its_count() {
        let msg = "a warning only this test holds".to_string();
        for _ in 0..3 {
            hold(msg.clone());
        }
        let held = HELD.lock().unwrap();
        let mine: Vec<_> = held.iter().filter(|(m, _)| *m == msg).collect();
        assert_eq!(mine.len(), 1);
        assert_eq!(mine[0].1, 3);
    }
}
