//! Progress of a running fit (stage, iteration, cost), for the command line's progress bar.
//!
//! The fit's stages report through [`report`]; a command that shows progress runs the fit
//! inside [`observe`], which routes the reports of this thread to its callback. Without an
//! observer a report costs one thread-local lookup.
use std::cell::RefCell;

/// One report: what the fit is doing, its iteration (0 before the first) and its cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Update<'a> {
    pub stage: &'a str,
    pub iteration: usize,
    /// The stage's cost (½‖r‖² of its residuals); NaN when it has none yet.
    pub cost: f64,
}

type Sink<'a> = Box<dyn FnMut(&Update) + 'a>;

thread_local! {
    static SINK: RefCell<Option<Sink<'static>>> = const { RefCell::new(None) };
}

/// Run `f` with the progress reports of this thread passed to `sink`.
pub fn observe<T>(sink: impl FnMut(&Update) + 'static, f: impl FnOnce() -> T) -> T {
    struct Restore(Option<Sink<'static>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let prev = self.0.take();
            SINK.with(|s| *s.borrow_mut() = prev);
        }
    }
    let prev = SINK.with(|s| s.borrow_mut().replace(Box::new(sink)));
    let _restore = Restore(prev);
    f()
}

/// Report progress to the observer of this thread, if any.
pub fn report(stage: &str, iteration: usize, cost: f64) {
    SINK.with(|s| {
        if let Ok(mut s) = s.try_borrow_mut() {
            if let Some(sink) = s.as_mut() {
                sink(&Update {
                    stage,
                    iteration,
                    cost,
                });
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    #[test]
    fn reports_reach_the_observer_only_inside_observe() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        report("before", 0, 1.0);
        let out = observe(
            move |u| s.lock().unwrap().push((u.stage.to_string(), u.iteration)),
            || {
                report("refine", 3, 2.0);
                7
            },
        );
        report("after", 0, 1.0);
        assert_eq!(out, 7);
        assert_eq!(*seen.lock().unwrap(), vec![("refine".to_string(), 3)]);
    }
}
