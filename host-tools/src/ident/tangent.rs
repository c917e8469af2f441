//! Numbers a free run can carry: `f64`, or a dual number that carries, beside each value,
//! its derivatives with respect to a few model parameters (forward sensitivities). One free
//! run in dual numbers gives as many Jacobian columns of the simulation error as it has
//! parameter lanes: the exact derivative of the discrete scheme the fit simulates, without
//! the truncation and cancellation of finite differences.
//!
//! The sub-step of the free run is implicit (its new velocity `w` is the root of a residual
//! `g(w; x, p)`, found in `f64`). The dual number has one more lane than parameters, for
//! `∂/∂w`: with the residual and the new state `s` evaluated at `w` seeded in that lane, the
//! implicit function theorem gives `ds/dp = ∂s/∂p − ∂s/∂w · (∂g/∂p)/(∂g/∂w)`
//! ([`RunScalar::on_root`]).
use control::effects::Effect;
use echidna::DualVec;
use num_traits::Float;

/// Parameter lanes of [`Tangent`]: Jacobian columns per dual free run. Every lane of a run
/// shares its values (the `exp` of the bristle update and the Stribeck curve, the sub-step's
/// divisions), which cost far more than a lane's products: one run of twelve lanes costs
/// less than two of six. Twelve covers the LuGre law, the motor constants and two or three
/// effect keys, the refinements of `fit --add`; those of two starts run side by side, so
/// the second core is used without splitting a Jacobian over two runs.
pub const PARAM_LANES: usize = 12;

/// The dual number of the sensitivity runs: [`PARAM_LANES`] parameter lanes, then the lane
/// of the sub-step's unknown.
pub type Tangent = DualVec<f64, { PARAM_LANES + 1 }>;

/// A number the free run computes in.
pub trait RunScalar: Float + Send + Sync + std::fmt::Debug + 'static {
    /// The value (real part).
    fn re(self) -> f64;
    /// A constant: no derivatives.
    fn constant(v: f64) -> Self;
    /// The unknown of an implicit sub-step at its value `w` (the root, found in `f64`),
    /// seeded in the unknown's lane.
    fn unknown(w: f64) -> Self;
    /// A value `s` computed from [`Self::unknown`], with the sub-step's residual `g` there:
    /// `s` on the root, its parameter lanes `∂s/∂p − ∂s/∂w·(∂g/∂p)/(∂g/∂w)`, its unknown's
    /// lane cleared.
    fn on_root(s: Self, g: Self) -> Self;
    /// The root `x` (found in `f64`) of a scalar equation `G(x) = 0` whose residual at `x`
    /// is `g` and whose slope there is `slope`: lanes `−(∂G/∂·)/slope`.
    fn root(x: f64, g: Self, slope: f64) -> Self;
}

impl RunScalar for f64 {
    fn re(self) -> f64 {
        self
    }
    fn constant(v: f64) -> Self {
        v
    }
    fn unknown(w: f64) -> Self {
        w
    }
    fn on_root(s: Self, _g: Self) -> Self {
        s
    }
    fn root(x: f64, _g: Self, _slope: f64) -> Self {
        x
    }
}

impl<const N: usize> RunScalar for DualVec<f64, N> {
    fn re(self) -> f64 {
        self.re
    }
    fn constant(v: f64) -> Self {
        DualVec::constant(v)
    }
    fn unknown(w: f64) -> Self {
        DualVec::with_tangent(w, N - 1)
    }
    fn on_root(s: Self, g: Self) -> Self {
        let gw = g.eps[N - 1];
        let sw = s.eps[N - 1];
        let mut out = s;
        out.eps[N - 1] = 0.0;
        if gw != 0.0 && gw.is_finite() && sw != 0.0 {
            let f = sw / gw;
            for (o, gp) in out.eps[..N - 1].iter_mut().zip(&g.eps[..N - 1]) {
                *o -= f * gp;
            }
        }
        out
    }
    fn root(x: f64, g: Self, slope: f64) -> Self {
        let mut out = DualVec::constant(x);
        if slope != 0.0 && slope.is_finite() {
            for (o, gp) in out.eps.iter_mut().zip(&g.eps) {
                *o = -gp / slope;
            }
        }
        out
    }
}

/// An effect with its parameters as constants of another number type.
pub fn lift_effect<D: RunScalar>(e: &Effect<f64>) -> Effect<D> {
    e.map(D::constant)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn implicit_root_has_the_implicit_functions_derivative() {
        // g(w; p) = w³ + p·w − 2 at p = 1: root w = 1, dw/dp = −w/(3w² + p) = −1/4; the state
        // s = w² then has ds/dp = 2w·dw/dp = −1/2.
        let p = Tangent::with_tangent(1.0, 0);
        let w = Tangent::unknown(1.0);
        let g = w * w * w + p * w - Tangent::constant(2.0);
        let s = Tangent::on_root(w * w, g);
        // 1e-15: the values are exact in binary (1, −1/2, 2); only rounding could move them.
        assert!((s.re - 1.0).abs() < 1e-15);
        assert!((s.eps[0] + 0.5).abs() < 1e-15, "{:?}", s.eps);
        assert_eq!(s.eps[PARAM_LANES], 0.0);
        // The scalar root: G(x) = x − p² at p = 1 (x = 1): dx/dp = 2.
        let x = Tangent::root(1.0, Tangent::constant(1.0) - p * p, 1.0);
        assert!((x.eps[0] - 2.0).abs() < 1e-15);
    }

    #[test]
    fn every_estimable_key_has_a_number() {
        use crate::effect_spec::EffectSpec;
        use crate::ident::free_params::effect_keys_of;
        for kind in &control::effects::EffectKind::ALL {
            let spec = EffectSpec {
                kind: *kind,
                values: Default::default(),
            };
            let e = spec.to_effect();
            let mut d = lift_effect::<Tangent>(&e);
            for (key, _, _) in effect_keys_of(&e) {
                let before = EffectSpec::from_effect(&e).get(key);
                let v = crate::effects::key_mut(&mut d, key)
                    .unwrap_or_else(|| panic!("{kind:?} has no number for {key}"));
                assert_eq!(v.re, before, "{kind:?}.{key}");
            }
        }
    }
}
