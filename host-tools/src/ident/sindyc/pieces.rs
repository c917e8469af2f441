//! A long free run in parallel pieces that gives the sequential run's states to the bit.
//!
//! The free run is a map `c_{k+1} = F_k(c_k)` of the carried state `c = (ẋ, z, I)` (the
//! angle is not carried: each step returns its increment, which the run adds up at the end).
//! The samples are cut into pieces; every piece but the first starts from a guess of the
//! state at its start (the measurement's), and all pieces run at once. Then, piece after
//! piece, the guessed start is replaced by the true one (the end of the piece before) and
//! the piece is run again from it until its state equals, bit for bit, the state the
//! guessed run reached at the same sample: `F_k` is deterministic, so from there on the
//! guessed run is the true one. A free run of a stable model forgets its start within a few
//! of its time constants, so the re-runs are short; a run that never meets its guess is
//! re-run to the end of the piece, which is the sequential run's cost. Either way the states
//! are the sequential run's, whatever the number of pieces or threads.

/// Fewest steps a piece is given: below this the re-run of a piece's start is a noticeable
/// part of its work.
pub const MIN_PIECE: usize = 1 << 15;

/// One step of a free run: the state `(Δθ, ẋ, z, I)` at sample `k + 1` from the one at `k`
/// (`Δθ`, the angle's increment over the step, is not an input).
pub trait Step<E>: Sync {
    fn step(&self, k: usize, s: &[f64; 4]) -> Result<[f64; 4], E>;
}

impl<E, F: Fn(usize, &[f64; 4]) -> Result<[f64; 4], E> + Sync> Step<E> for F {
    fn step(&self, k: usize, s: &[f64; 4]) -> Result<[f64; 4], E> {
        self(k, s)
    }
}

/// The carried part of a state, as bits (so that `-0.0` and `0.0`, or two NaNs, are told
/// apart exactly as the map sees them).
fn carried(s: &[f64; 4]) -> [u64; 3] {
    [s[1].to_bits(), s[2].to_bits(), s[3].to_bits()]
}

/// The states of samples `0..n` from `start`: `out[0] = start` and `out[k + 1] =
/// step(k, out[k])`, in pieces of at least [`MIN_PIECE`] steps, `pieces` at most;
/// `guess(k)` is a state near the one at sample `k`. The angle entry of every state but the
/// first is the increment into it. Stops at the first error as the sequential run does,
/// with the same error.
pub fn run<E: Send>(
    n: usize,
    start: [f64; 4],
    step: &impl Step<E>,
    guess: &(impl Fn(usize) -> [f64; 4] + Sync),
    pieces: usize,
) -> Result<Vec<[f64; 4]>, E> {
    use rayon::prelude::*;
    let steps = n.saturating_sub(1);
    let count = pieces.min(steps / MIN_PIECE).max(1);
    // Piece p takes the steps bounds[p]..bounds[p + 1].
    let bounds: Vec<usize> = (0..=count).map(|p| p * steps / count).collect();
    // Each piece's states after each of its steps, and the error that stopped it.
    let runs: Vec<(Vec<[f64; 4]>, Option<E>)> = (0..count)
        .into_par_iter()
        .map(|p| {
            let (k0, k1) = (bounds[p], bounds[p + 1]);
            let mut s = if p == 0 { start } else { guess(k0) };
            let mut states = Vec::with_capacity(k1 - k0);
            for k in k0..k1 {
                match step.step(k, &s) {
                    Ok(next) => {
                        states.push(next);
                        s = next;
                    }
                    Err(e) => return (states, Some(e)),
                }
            }
            (states, None)
        })
        .collect();
    let mut out = Vec::with_capacity(n);
    out.push(start);
    for (p, (mut states, err)) in runs.into_iter().enumerate() {
        let k0 = bounds[p];
        let mut s = *out.last().expect("the start is in");
        // Piece 0 started from the true state; the others until they meet their guess.
        let mut rerun = p > 0 && carried(&s) != carried(&guess(k0));
        let mut k = k0;
        while rerun && k < bounds[p + 1] {
            let next = step.step(k, &s)?;
            let j = k - k0;
            rerun = !(j < states.len() && carried(&states[j]) == carried(&next));
            if j < states.len() {
                states[j] = next;
            } else {
                states.push(next);
            }
            s = next;
            k += 1;
        }
        let complete = k0 + states.len() == bounds[p + 1];
        out.extend(states);
        if !complete {
            // The guessed run stopped at an error the true run reaches from the same state.
            if let Some(e) = err {
                return Err(e);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damped, driven state with a sign-like term (the structure of a motor's free run).
    fn damped(k: usize, s: &[f64; 4]) -> Result<[f64; 4], String> {
        let u = ((k / 700) % 3) as f64 - 1.0;
        let w = s[1] + 0.012 * (-40.0 * s[1] + 300.0 * s[3] - 5.0 * (2.0 * s[1]).tanh());
        let i = 0.2 * s[3] + 0.8 * (u - 0.05 * s[1]);
        if !w.is_finite() {
            return Err(format!("diverged at {k}"));
        }
        Ok([0.012 * s[1], w, 0.0, i])
    }

    fn sequential<E>(
        n: usize,
        start: [f64; 4],
        step: impl Fn(usize, &[f64; 4]) -> Result<[f64; 4], E>,
    ) -> Result<Vec<[f64; 4]>, E> {
        let mut out = vec![start];
        for k in 0..n - 1 {
            let next = step(k, out.last().unwrap())?;
            out.push(next);
        }
        Ok(out)
    }

    fn bits(v: &[[f64; 4]]) -> Vec<[u64; 4]> {
        v.iter().map(|s| s.map(f64::to_bits)).collect()
    }

    #[test]
    fn pieces_give_the_sequential_states_to_the_bit() {
        let n = 5 * MIN_PIECE + 123;
        let start = [0.3, 2.0, 0.0, 0.1];
        let want = sequential(n, start, damped).unwrap();
        // A guess far from the state: the re-runs must carry the true one in.
        let guess = |_k: usize| [0.0, 50.0, 0.0, -3.0];
        for pieces in [1, 2, 3, 5, 8] {
            let got = run(n, start, &damped, &guess, pieces).unwrap();
            assert_eq!(bits(&got), bits(&want), "{pieces} pieces");
        }
    }

    #[test]
    fn a_run_that_never_forgets_its_start_is_rerun_whole() {
        // An undamped state keeps its start forever: every piece is re-run.
        let n = 3 * MIN_PIECE;
        let drift = |k: usize, s: &[f64; 4]| -> Result<[f64; 4], ()> {
            Ok([s[1], s[1] + 1e-3 * (k % 7) as f64, s[2], s[3]])
        };
        let start = [0.0, 1.0, 0.5, 0.0];
        let want = sequential(n, start, drift).unwrap();
        let got = run(n, start, &drift, &|_| [0.0; 4], 3).unwrap();
        assert_eq!(bits(&got), bits(&want));
    }

    #[test]
    fn the_first_error_is_the_sequential_runs() {
        let n = 4 * MIN_PIECE;
        let start = [0.0, 1.0, 0.0, 0.0];
        // A guess far off fails at once (a velocity beyond 100), a near one does not.
        for (fail_at, guessed) in [(MIN_PIECE + 500, 1000.0), (2 * MIN_PIECE + 5000, 0.5)] {
            let step = |k: usize, s: &[f64; 4]| -> Result<[f64; 4], usize> {
                if k == fail_at || s[1] > 100.0 {
                    return Err(k);
                }
                damped(k, s).map_err(|_| usize::MAX)
            };
            let want = sequential(n, start, step).unwrap_err();
            assert_eq!(want, fail_at);
            let got = run(n, start, &step, &|_| [0.0, guessed, 0.0, 0.0], 4).unwrap_err();
            assert_eq!(got, want, "guess {guessed}");
        }
    }

    #[test]
    fn a_long_free_run_equals_the_sequential_run_of_its_start() {
        use crate::ident::sindyc::simulate::{simulate, Limits};
        use crate::log::{MotorLog, Plant};
        use control::sindy::{SindyModel, SparseEq, Term};
        // The paper motor's structure: sign-like friction (steps across it are split), a
        // fast current; voltage steps with rests between them.
        let mut m = SindyModel::empty(100.0, 3.0, 1.0);
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -4.8),
            (Term::I, 216.0),
            (Term::TanhXdot, -243.0),
            (Term::StribeckXdot, -90.0),
        ])
        .unwrap();
        m.idot =
            SparseEq::from_slice(&[(Term::Xdot, -260.0), (Term::I, -833.0), (Term::U, 3672.0)])
                .unwrap();
        let dt = 0.012;
        let log = |n: usize| MotorLog {
            t: (0..n).map(|k| k as f64 * dt).collect(),
            u: (0..n)
                .map(|k| [0.0, 2.5, 0.0, -4.0, 1.0][(k / 377) % 5])
                .collect(),
            theta: (0..n).map(|k| (k as f64 * 0.01).sin()).collect(),
            i: Some(vec![0.5; n]),
            ..MotorLog::default()
        };
        let n = 2 * MIN_PIECE + 1000;
        let long = simulate(&m, Plant::Voltage, &log(n), Limits::default()).unwrap();
        // A log shorter than two pieces runs in one.
        let short = simulate(
            &m,
            Plant::Voltage,
            &log(2 * MIN_PIECE - 1),
            Limits::default(),
        )
        .unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let k = short.theta.len();
        assert_eq!(bits(&long.theta[..k]), bits(&short.theta));
        assert_eq!(bits(&long.omega[..k]), bits(&short.omega));
        assert_eq!(
            bits(&long.i.as_ref().unwrap()[..k]),
            bits(short.i.as_ref().unwrap())
        );
        assert!(long.omega.iter().any(|w| w.abs() > 1.0));
    }
}
