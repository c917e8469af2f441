//! Sine and cosine in f32 arithmetic only, for the board.
//!
//! The periodic terms the board evaluates (cogging `sin(k·θ)`, SINDYc's `sin(k·x)` and
//! `cos(k·x)`, the multisine excitations) need a sine and a cosine. `libm`'s `sinf`/`cosf`
//! reduce their argument and evaluate their kernels in f64, which a Cortex-M4F does in
//! software (about 7 KB of flash with the f64 routines they pull in). Here everything is f32:
//!
//! 1. Range reduction (Cody-Waite): `k = round(x·2/π)`, `r = x − k·π/2` with π/2 split into
//!    three f32 parts `P1 + P2 + P3`; `P1` and `P2` have at most 12 significant bits, so
//!    `k·P1` and `k·P2` are exact for `|k| < 2^12` (`|x|` below about 6434 rad) and `r` is
//!    accurate to a few ulp of `r`. `|r| ≤ π/4`.
//! 2. Kernels on `[−π/4, π/4]`: the Taylor series of sin to `r⁹` (truncation below
//!    `(π/4)¹¹/11! ≈ 1.8·10⁻⁹`) and of cos to `r¹⁰` (below `(π/4)¹²/12! ≈ 1.1·10⁻¹⁰`), both
//!    far under half an ulp of a result near 1 (`6·10⁻⁸`).
//! 3. The quadrant `k mod 4` picks ±sin r or ±cos r.
//!
//! **Accuracy** (tests below, against f64 `std` on the same f32 argument over a dense grid):
//! absolute error at most [`MAX_ERROR`] for `|x| ≤` [`EXACT_RANGE`]. Beyond it `k·P1` is
//! rounded, and the error grows as the argument's own spacing: at most
//! `MAX_ERROR + ulp(x)` (an f32 argument near `x` is itself uncertain by `ulp(x)/2`).
//! For `|x| > 2^24` (consecutive f32 values 2 or more apart) that bound is 2 or more, met
//! by any result in [−1, 1]; there `y = x·2/π` is rounded and `k` may be one too high, which
//! is harmless for the same reason. For `|x| ≥` [`PHASELESS`] (consecutive f32 values more
//! than π apart: the argument holds no phase) both return 0; NaN and ±∞ give NaN.
//!
//! The firmware and the emulated board run this same code, so their results agree bit for
//! bit (QEMU parity).
use num_traits::Float;

/// Largest absolute error of [`sin`] and [`cos`] for `|x| ≤` [`EXACT_RANGE`] (measured:
/// 8.6·10⁻⁸, under 1.5 ulp of 1; a correctly rounded f32 sine errs by up to 3·10⁻⁸).
pub const MAX_ERROR: f32 = 1.0e-7;
/// Range [rad] over which the range reduction is exact: `|k| < 2^12` quarter turns.
pub const EXACT_RANGE: f32 = 6400.0;
/// From this `|x|` [rad] on, f32 arguments are more than π apart: sin and cos return 0.
pub const PHASELESS: f32 = 33_554_432.0; // 2^25

/// π/2 in three parts: `P1` and `P2` with 12 significant bits each, `P3` the rest rounded to
/// f32 (1.5703125, 4.8375130e-4, 7.5497901e-8).
const P1: f32 = f32::from_bits(0x3FC9_0000);
const P2: f32 = f32::from_bits(0x39FD_A000);
const P3: f32 = f32::from_bits(0x33A2_2169);
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;

/// `(k mod 4, r)` with `x = k·π/2 + r`, `|r| ≤ π/4` (module docs, step 1).
#[inline(always)]
fn reduce(x: f32) -> (u32, f32) {
    let y = x * FRAC_2_PI;
    // Round half away from zero; |y| < 2^25 here, so the cast cannot saturate.
    let k = (y + 0.5f32.copysign(y)) as i32;
    let kf = k as f32;
    let r = ((x - kf * P1) - kf * P2) - kf * P3;
    (k as u32 & 3, r)
}

/// Taylor kernel of sin on `[−π/4, π/4]` (module docs, step 2).
#[inline(always)]
fn sin_kernel(r: f32) -> f32 {
    let r2 = r * r;
    let p = -1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0)));
    r + r * r2 * p
}

/// Taylor kernel of cos on `[−π/4, π/4]` (module docs, step 2).
#[inline(always)]
fn cos_kernel(r: f32) -> f32 {
    let r2 = r * r;
    let p = 1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 - r2 * (1.0 / 3_628_800.0)));
    1.0 + r2 * (-0.5 + r2 * p)
}

/// `(sin x, cos x)` in f32 arithmetic (module docs for the accuracy).
pub fn sin_cos(x: f32) -> (f32, f32) {
    if x.is_nan() || x.is_infinite() {
        return (f32::NAN, f32::NAN);
    }
    if x.abs() >= PHASELESS {
        return (0.0, 0.0);
    }
    let (q, r) = reduce(x);
    let (s, c) = (sin_kernel(r), cos_kernel(r));
    match q {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// sin x [x in rad] in f32 arithmetic (the one kernel its quadrant needs; the same bits as
/// [`sin_cos`]'s sine).
pub fn sin(x: f32) -> f32 {
    if x.is_nan() || x.is_infinite() {
        return f32::NAN;
    }
    if x.abs() >= PHASELESS {
        return 0.0;
    }
    let (q, r) = reduce(x);
    match q {
        0 => sin_kernel(r),
        1 => cos_kernel(r),
        2 => -sin_kernel(r),
        _ => -cos_kernel(r),
    }
}

/// cos x [x in rad] in f32 arithmetic (the one kernel its quadrant needs; the same bits as
/// [`sin_cos`]'s cosine).
pub fn cos(x: f32) -> f32 {
    if x.is_nan() || x.is_infinite() {
        return f32::NAN;
    }
    if x.abs() >= PHASELESS {
        return 0.0;
    }
    let (q, r) = reduce(x);
    match q {
        0 => cos_kernel(r),
        1 => -sin_kernel(r),
        2 => -cos_kernel(r),
        _ => sin_kernel(r),
    }
}

/// sin x for the generic equations: this module's [`sin`] in f32 (the board's type), the
/// platform's own sine in f64 (host identification keeps f64 accuracy).
#[inline(always)]
pub fn sin_of<F: Float>(x: F) -> F {
    if core::mem::size_of::<F>() == 4 {
        F::from(sin(x.to_f32().unwrap_or(f32::NAN))).unwrap_or_else(F::nan)
    } else {
        x.sin()
    }
}

/// cos x for the generic equations (see [`sin_of`]).
#[inline(always)]
pub fn cos_of<F: Float>(x: F) -> F {
    if core::mem::size_of::<F>() == 4 {
        F::from(cos(x.to_f32().unwrap_or(f32::NAN))).unwrap_or_else(F::nan)
    } else {
        x.cos()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// Largest error of `f` against f64 `std` over `n` points evenly spread on `[lo, hi]`.
    fn worst(f: fn(f32) -> f32, g: fn(f64) -> f64, lo: f32, hi: f32, n: u32) -> (f64, f32) {
        let mut w = (0.0f64, lo);
        for i in 0..=n {
            let x = lo + (hi - lo) * (i as f32 / n as f32);
            let e = (f(x) as f64 - g(x as f64)).abs();
            if e > w.0 {
                w = (e, x);
            }
        }
        w
    }

    #[test]
    fn sine_and_cosine_are_within_the_stated_error_over_the_exact_range() {
        for (name, f, g) in [
            ("sin", sin as fn(f32) -> f32, f64::sin as fn(f64) -> f64),
            ("cos", cos, f64::cos),
        ] {
            let (e, x) = worst(f, g, -EXACT_RANGE, EXACT_RANGE, 4_000_000);
            assert!(e <= MAX_ERROR as f64, "{name}: error {e:e} at x = {x}");
            // Near zero, where results are tiny, the dense grid of small arguments.
            let (e, x) = worst(f, g, -4.0, 4.0, 1_000_000);
            assert!(e <= MAX_ERROR as f64, "{name}: error {e:e} at x = {x}");
        }
    }

    #[test]
    fn every_f32_near_a_quadrant_boundary_is_within_the_stated_error() {
        // Every f32 within 64 ulp of k·π/4 for the first 64 boundaries: where the reduction
        // switches quadrant and where cancellation in `x − k·π/2` is largest.
        for k in 1..64 {
            let b = (k as f64 * core::f64::consts::FRAC_PI_4) as f32;
            let mut x = f32::from_bits(b.to_bits() - 64);
            for _ in 0..128 {
                for (f, g) in [
                    (sin as fn(f32) -> f32, f64::sin as fn(f64) -> f64),
                    (cos, f64::cos),
                ] {
                    let e = (f(x) as f64 - g(x as f64)).abs();
                    assert!(e <= MAX_ERROR as f64, "error {e:e} at x = {x}");
                }
                x = f32::from_bits(x.to_bits() + 1);
            }
        }
    }

    #[test]
    fn large_arguments_err_by_at_most_their_own_spacing() {
        for (f, g) in [
            (sin as fn(f32) -> f32, f64::sin as fn(f64) -> f64),
            (cos, f64::cos),
        ] {
            for i in 0..=200_000u32 {
                let x = EXACT_RANGE * (1.0 + 5000.0 * i as f32 / 200_000.0);
                let ulp = f32::from_bits(x.to_bits() + 1) - x;
                let e = (f(x) as f64 - g(x as f64)).abs();
                assert!(
                    e <= (MAX_ERROR + ulp) as f64,
                    "error {e:e} at x = {x} (ulp {ulp})"
                );
            }
        }
    }

    #[test]
    fn sin_and_cos_give_the_bits_of_sin_cos() {
        for i in 0..200_000u32 {
            let x = (i as f32 - 100_000.0) * 0.0731;
            let (s, c) = sin_cos(x);
            assert_eq!(sin(x).to_bits(), s.to_bits(), "{x}");
            assert_eq!(cos(x).to_bits(), c.to_bits(), "{x}");
        }
        // Beyond 2^24 the stated bound (the argument's spacing) is 2 or more: any result in
        // [−1, 1] meets it, even with k one quarter turn too high.
        let x = 16_777_216.0f32 * 1.5;
        let ulp = f32::from_bits(x.to_bits() + 1) - x;
        assert!(MAX_ERROR + ulp >= 2.0 && sin(x).abs() <= 1.0 && cos(x).abs() <= 1.0);
    }

    #[test]
    fn sin_and_cos_are_odd_and_even() {
        for i in 0..10_000 {
            let x = i as f32 * 0.731;
            assert_eq!(sin(-x), -sin(x));
            assert_eq!(cos(-x), cos(x));
        }
    }

    #[test]
    fn non_finite_arguments_give_nan_and_phaseless_ones_zero() {
        assert!(sin(f32::NAN).is_nan() && cos(f32::INFINITY).is_nan());
        assert!(sin(f32::NEG_INFINITY).is_nan());
        assert_eq!(sin_cos(PHASELESS), (0.0, 0.0));
        assert_eq!(sin_cos(-1.0e30), (0.0, 0.0));
    }

    #[test]
    fn the_generic_forms_use_the_f32_kernel_for_f32_and_std_for_f64() {
        assert_eq!(sin_of(1.234f32).to_bits(), sin(1.234).to_bits());
        assert_eq!(cos_of(1.234f32).to_bits(), cos(1.234).to_bits());
        assert_eq!(sin_of(1.234f64), 1.234f64.sin());
        assert_eq!(cos_of(1.234f64), 1.234f64.cos());
    }
}
