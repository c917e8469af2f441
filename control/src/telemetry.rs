//! Control-loop telemetry: loop period, jitter, overruns, cycles per step and lost Hall
//! edges, gathered every period and reported once per window of [`WINDOW_PERIODS`]
//! periods (≈ 1 s): the firmware prints each report through defmt, and the board sends it
//! to the host as `BoardMsg::Telemetry` while a run streams samples (and on
//! `HostMsg::ReadTelemetry`), so that `motorid record` writes it into the log.
use serde::{Deserialize, Serialize};

/// Periods per report: 83 × 12 ms = 0.996 s.
pub const WINDOW_PERIODS: u32 = 83;

/// One report.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Telemetry {
    /// Periods the window covers.
    pub periods: u32,
    /// Mean loop period over the window [µs] (nominal: 12 000 µs).
    pub period_us: f32,
    /// Largest deviation of one period from the nominal period in the window [µs].
    pub jitter_us: f32,
    /// Periods that overran (started more than one period late) since boot.
    pub overruns: u32,
    /// Most cycles one period's work took in the window (the firmware's DWT cycle counter at
    /// 170 MHz: 2 040 000 cycles are one period); 0 where there is no cycle counter (the
    /// emulated board).
    pub step_cycles_max: u32,
    /// Hall edges lost since boot because more came in one period than the capture queue
    /// holds (`crate::step::MAX_EDGES`).
    pub edges_lost: u32,
}

/// What one period measured, for [`LoopStats::record`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PeriodTiming {
    /// Time since the previous period started [µs]; not finite or not positive: unknown
    /// (the first period), left out of the window's mean and jitter.
    pub period_us: f32,
    /// Cycles the previous period's work took (0: not measured).
    pub step_cycles: u32,
    /// The period overran.
    pub overrun: bool,
    /// Hall edges lost since boot (the capture's running count).
    pub edges_lost: u32,
}

/// Accumulates [`PeriodTiming`]s into windows.
#[derive(Debug, Clone, Default)]
pub struct LoopStats {
    periods: u32,
    timed: u32,
    sum_us: f32,
    jitter_us: f32,
    cycles_max: u32,
    overruns: u32,
    edges_lost: u32,
    last: Option<Telemetry>,
}

impl LoopStats {
    /// No period seen yet.
    pub const fn new() -> Self {
        LoopStats {
            periods: 0,
            timed: 0,
            sum_us: 0.0,
            jitter_us: 0.0,
            cycles_max: 0,
            overruns: 0,
            edges_lost: 0,
            last: None,
        }
    }

    /// Adds one period of nominal length `nominal_us` [µs]; returns the report when it
    /// completes a window.
    pub fn record(&mut self, t: PeriodTiming, nominal_us: f32) -> Option<Telemetry> {
        self.periods += 1;
        if t.period_us.is_finite() && t.period_us > 0.0 {
            self.timed += 1;
            self.sum_us += t.period_us;
            let dev = (t.period_us - nominal_us).abs();
            if dev > self.jitter_us {
                self.jitter_us = dev;
            }
        }
        if t.step_cycles > self.cycles_max {
            self.cycles_max = t.step_cycles;
        }
        if t.overrun {
            self.overruns = self.overruns.saturating_add(1);
        }
        self.edges_lost = t.edges_lost;
        if self.periods < WINDOW_PERIODS {
            return None;
        }
        let report = self.current();
        self.last = Some(report);
        self.periods = 0;
        self.timed = 0;
        self.sum_us = 0.0;
        self.jitter_us = 0.0;
        self.cycles_max = 0;
        Some(report)
    }

    /// The window so far (the counts since boot are always current).
    pub fn current(&self) -> Telemetry {
        Telemetry {
            periods: self.periods,
            period_us: if self.timed > 0 {
                self.sum_us / self.timed as f32
            } else {
                0.0
            },
            jitter_us: self.jitter_us,
            overruns: self.overruns,
            step_cycles_max: self.cycles_max,
            edges_lost: self.edges_lost,
        }
    }

    /// The last complete window, or the window so far before the first one completes.
    pub fn latest(&self) -> Telemetry {
        self.last.unwrap_or_else(|| self.current())
    }
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    #[test]
    fn a_window_reports_mean_period_worst_jitter_and_counts() {
        let mut s = LoopStats::new();
        let nominal = 12_000.0;
        let mut report = None;
        for k in 0..WINDOW_PERIODS {
            let t = PeriodTiming {
                // The first period is not timed; one is 30 µs late, the next 30 µs early.
                period_us: match k {
                    0 => f32::NAN,
                    10 => nominal + 30.0,
                    11 => nominal - 30.0,
                    _ => nominal,
                },
                step_cycles: 1000 + k,
                overrun: k == 40,
                edges_lost: k / 20,
            };
            let r = s.record(t, nominal);
            assert_eq!(r.is_some(), k + 1 == WINDOW_PERIODS, "period {k}");
            report = r.or(report);
        }
        let r = report.unwrap();
        assert_eq!(r.periods, WINDOW_PERIODS);
        assert!((r.period_us - nominal).abs() < 0.01, "{}", r.period_us);
        // 1e-3 µs: an f32 ulp of the 12,030 µs period the jitter is taken from.
        assert!((r.jitter_us - 30.0).abs() < 1e-3);
        assert_eq!(r.step_cycles_max, 1000 + WINDOW_PERIODS - 1);
        assert_eq!(r.overruns, 1);
        assert_eq!(r.edges_lost, (WINDOW_PERIODS - 1) / 20);
        assert_eq!(s.latest(), r);
        // The next window starts afresh but keeps the counts since boot.
        s.record(
            PeriodTiming {
                period_us: nominal,
                step_cycles: 5,
                overrun: true,
                edges_lost: 9,
            },
            nominal,
        );
        let c = s.current();
        assert_eq!((c.periods, c.step_cycles_max, c.jitter_us), (1, 5, 0.0));
        assert_eq!((c.overruns, c.edges_lost), (2, 9));
    }
}
