//! Root of a scalar equation `f(x) = 0` for the implicit integrator: bracket search from a
//! guess, then the Illinois variant of regula falsi with periodic bisection.
//!
//! Written here rather than taken from a crate because the integrator calls it twice per
//! 0.2 ms step: it must reuse every function value (the `roots` crate's Brent evaluates both
//! bracket ends again on every iteration) and must stop cleanly at a *jump* of `f` (a hard
//! `sgn(ω)` in a user's load closure), where no exact root exists and the answer is the
//! jump's location.

/// Find `x` with `f(x) = 0`, or the location of a sign change of `f`, to within `xtol`.
///
/// `x0` is the first guess and `step0` the first search step. The search walks downhill in
/// `|f|` assuming `f` increases (true for every residual of the emulator), widening the step
/// fourfold each time, until the sign changes; then it narrows the bracket. If no sign
/// change is found in 200 widenings the last point is returned.
pub fn find_root(mut f: impl FnMut(f64) -> f64, x0: f64, step0: f64, xtol: f64) -> f64 {
    let f0 = f(x0);
    if f0 == 0.0 || !f0.is_finite() {
        return x0;
    }
    let dir = if f0 > 0.0 { -1.0 } else { 1.0 };
    let (mut a, mut fa) = (x0, f0);
    let mut step = if step0.is_finite() && step0 > xtol {
        step0
    } else {
        xtol.max(1e-300)
    };
    let (mut b, mut fb);
    let mut tries = 0;
    loop {
        b = a + dir * step;
        fb = f(b);
        if fb == 0.0 {
            return b;
        }
        if !fb.is_finite() {
            // Stepped too far: come back half way.
            step *= 0.5;
            tries += 1;
            if tries > 200 {
                return a;
            }
            continue;
        }
        if (fb > 0.0) != (fa > 0.0) {
            break;
        }
        a = b;
        fa = fb;
        step *= 4.0;
        tries += 1;
        if tries > 200 {
            return b;
        }
    }
    // Invariant: fa and fb have opposite signs.
    let mut side = 0i8;
    for iter in 0..200 {
        if (b - a).abs() <= xtol {
            break;
        }
        let c = if iter % 4 == 3 {
            0.5 * (a + b)
        } else {
            let c = (a * fb - b * fa) / (fb - fa);
            if c.is_finite() && (c - a) * (c - b) < 0.0 {
                c
            } else {
                0.5 * (a + b)
            }
        };
        let fc = f(c);
        if fc == 0.0 {
            return c;
        }
        if (fc > 0.0) == (fb > 0.0) {
            b = c;
            fb = fc;
            if side == -1 {
                fa *= 0.5;
            }
            side = -1;
        } else {
            a = c;
            fa = fc;
            if side == 1 {
                fb *= 0.5;
            }
            side = 1;
        }
    }
    // The end with the smaller residual (both are within xtol of the root or jump).
    if fa.abs() <= fb.abs() {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_root_to_tolerance() {
        let mut calls = 0;
        let x = find_root(
            |x| {
                calls += 1;
                x * x * x + 2.0 * x - 5.0
            },
            0.0,
            0.1,
            1e-12,
        );
        // 1e-9: the slope there (about 7) times xtol 1e-12, with room; under 60 calls: a few
        // widenings, then about 40 halvings from a bracket of order 1 to 1e-12.
        assert!((x * x * x + 2.0 * x - 5.0).abs() < 1e-9, "x = {x}");
        assert!(calls < 60, "{calls} calls");
    }

    #[test]
    fn jump_is_located() {
        // f jumps from −1 to +1 at x = 0.3: no root, the jump's place is the answer.
        let x = find_root(|x| if x < 0.3 { -1.0 } else { 1.0 }, -5.0, 0.01, 1e-10);
        // 1e-9: ten times the xtol of 1e-10 asked.
        assert!((x - 0.3).abs() < 1e-9, "x = {x}");
    }

    #[test]
    fn steep_tanh() {
        let x = find_root(|x| (x / 1e-3).tanh() + 0.01 * x - 0.5, 10.0, 1.0, 1e-13);
        // 1e-8: the slope (1000) times xtol 1e-13, with room.
        assert!(((x / 1e-3).tanh() + 0.01 * x - 0.5).abs() < 1e-8, "x = {x}");
    }
}
