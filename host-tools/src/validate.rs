//! Validated numbers: the one place that decides what a finite, physical value is.
//!
//! Every number that comes from outside (a log's `# sample_period` and time column, a
//! MODEL.toml field, an effect spec's key, a numeric command-line flag) goes through one of
//! these checks before it sizes an allocation or a loop. The messages say what is wrong with
//! the value; the caller prefixes the file and the field (or clap the flag).
//!
//! * [`finite`], [`in_range`]: the building blocks (`NaN is not a finite number`,
//!   `1e30 is outside 0 .. 1000`).
//! * [`sample_period`]: a sample period or time step in the physical range
//!   [`MIN_SAMPLE_PERIOD`] .. [`MAX_SAMPLE_PERIOD`].
//! * `parse_*`: clap value parsers for numeric flags (`#[arg(value_parser = ...)]`), so a bad
//!   flag is refused before the command runs, with clap's one `error:` line naming the flag.

/// Shortest sample period (or median time step) a log may have [s]: 1 µs (1 MHz).
pub const MIN_SAMPLE_PERIOD: f64 = 1e-6;
/// Longest sample period (or median time step) a log may have [s].
pub const MAX_SAMPLE_PERIOD: f64 = 10.0;
/// Longest single step of a log's time column [s] (a pause in a recording, about 11 days):
/// beyond, the time column is not a recording's.
pub const MAX_TIME_STEP: f64 = 1e6;

/// `v` as a message fragment (public for messages elsewhere): `NaN`, `inf`, `-inf` or the number.
pub fn show(v: f64) -> String {
    if v.is_nan() {
        "NaN".to_string()
    } else if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Ok when `v` is a finite number.
pub fn finite(v: f64) -> Result<f64, String> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{} is not a finite number", show(v)))
    }
}

/// Ok when `v` is finite and `lo <= v <= hi`.
pub fn in_range(v: f64, lo: f64, hi: f64) -> Result<f64, String> {
    finite(v)?;
    if v < lo || v > hi {
        return Err(format!(
            "{} is outside {} .. {}",
            show(v),
            show(lo),
            show(hi)
        ));
    }
    Ok(v)
}

/// Ok when `v` is finite and `0 < v <= hi`.
pub fn positive_at_most(v: f64, hi: f64) -> Result<f64, String> {
    finite(v)?;
    if v <= 0.0 || v > hi {
        return Err(format!("{} is outside (0, {}]", show(v), show(hi)));
    }
    Ok(v)
}

/// Finest nonzero angle quantum [rad]: 1e-12, finer than any encoder's (2^32 counts a turn
/// is 1.5e-9 rad).
pub const MIN_ANGLE_QUANTUM: f64 = 1e-12;

/// Ok when `v` is an angle sensor's quantum [rad]: 0 (not quantised) or
/// [`MIN_ANGLE_QUANTUM`] .. 2π (one step a revolution, the coarsest sensor there is).
pub fn angle_quantum(v: f64) -> Result<f64, String> {
    in_range(v, 0.0, std::f64::consts::TAU)?;
    if v > 0.0 && v < MIN_ANGLE_QUANTUM {
        return Err(format!(
            "{} rad is finer than any angle sensor (at least 1e-12 rad, or 0 for none)",
            show(v)
        ));
    }
    Ok(v)
}

/// Ok when `v` (seconds) is a sample period a motor log can have.
pub fn sample_period(v: f64) -> Result<f64, String> {
    finite(v)?;
    if !(MIN_SAMPLE_PERIOD..=MAX_SAMPLE_PERIOD).contains(&v) {
        return Err(format!(
            "{} s is outside the physical range 1 µs .. 10 s",
            show(v)
        ));
    }
    Ok(v)
}

/// `s` as a whole number `lo ..= hi` (`'abc' is not a whole number`, `300 is outside 1 .. 255`).
pub fn whole_number(s: &str, lo: u64, hi: u64) -> Result<u64, String> {
    let n: u64 = s.trim().parse().map_err(|_| {
        format!(
            "'{}' is not a whole number {lo} .. {hi}",
            crate::log::echo(s)
        )
    })?;
    if !(lo..=hi).contains(&n) {
        return Err(format!("{n} is outside {lo} .. {hi}"));
    }
    Ok(n)
}

/// `s` as a finite number.
pub fn number(s: &str) -> Result<f64, String> {
    finite(plain_number(s)?)
}

fn plain_number(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .map_err(|_| format!("'{}' is not a number", crate::log::echo(s)))
}

/// Defines a clap value parser `fn(&str) -> Result<T, String>` checking a range.
macro_rules! range_parser {
    ($(#[$doc:meta])* $name:ident, $t:ty, $check:expr) => {
        $(#[$doc])*
        pub fn $name(s: &str) -> Result<$t, String> {
            let v = plain_number(s)?;
            let check: fn(f64) -> Result<f64, String> = $check;
            check(v)?;
            Ok(v as $t)
        }
    };
}

/// Longest simulated signal [s]: 10⁴ s, 833,334 samples of 12 ms (a simulation's memory
/// grows with its length).
pub const MAX_SIM_DURATION: f64 = 1e4;
/// Shortest simulated signal [s]: two samples of 12 ms, the fewest a log holds.
pub const MIN_SIM_DURATION: f64 = 0.024;

range_parser!(
    /// `simulate --duration` [s]: two samples .. [`MAX_SIM_DURATION`].
    parse_duration, f64, |v| in_range(v, MIN_SIM_DURATION, MAX_SIM_DURATION)
);
range_parser!(
    /// `simulate --fine-step` [s]: 1 µs .. 12 ms (one sample).
    parse_fine_step, f64, |v| in_range(v, 1e-6, 0.012)
);
range_parser!(
    /// `simulate --noise` [A]: 0 .. 100.
    parse_noise, f64, |v| in_range(v, 0.0, 100.0)
);
range_parser!(
    /// `board --speed` (time factor): 0.001 .. 1000.
    parse_speed, f64, |v| in_range(v, 1e-3, 1e3)
);
range_parser!(
    /// Speed-loop proportional gain [V per rad/s]: 0 .. 1000.
    parse_kp, f32, |v| in_range(v, 0.0, control::blob::MAX_KP.into())
);
range_parser!(
    /// Speed-loop integral gain [V per rad]: 0 .. 10000.
    parse_ki, f32, |v| in_range(v, 0.0, control::blob::MAX_KI.into())
);
range_parser!(
    /// Voltage limit of the speed loop [V]: (0, 26], the board's rated bus.
    parse_u_max, f32, |v| positive_at_most(v, control::blob::RATED_VBUS_MAX.into())
);
range_parser!(
    /// Weight of the friction compensation: 0 .. 10.
    parse_comp_gain, f32, |v| in_range(v, 0.0, control::blob::MAX_COMP_GAIN.into())
);
range_parser!(
    /// Edge-timing standstill timeout [s]: 0.1 ms .. 60 s.
    parse_edge_timeout, f32, |v| in_range(v, 1e-4, 60.0)
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_problem() {
        assert_eq!(finite(f64::NAN).unwrap_err(), "NaN is not a finite number");
        assert_eq!(
            finite(f64::NEG_INFINITY).unwrap_err(),
            "-inf is not a finite number"
        );
        assert!(sample_period(1e-9).unwrap_err().contains("1 µs .. 10 s"));
        assert!(sample_period(0.012).is_ok());
        assert!(parse_kp("nan").unwrap_err().contains("not a finite"));
        assert!(parse_kp("-1").unwrap_err().contains("outside"));
        assert!(parse_ki("-1e30").is_err());
        assert!(parse_noise("1e308").is_err());
        assert!(parse_fine_step("1e-300").is_err());
        assert!(parse_duration("1e12").is_err());
        assert!(parse_speed("1e-300").is_err());
        assert!(parse_edge_timeout("-1").is_err());
        assert!(parse_kp("abc").unwrap_err().contains("not a number"));
        assert_eq!(parse_kp("0.05").unwrap(), 0.05f32);
    }
}
