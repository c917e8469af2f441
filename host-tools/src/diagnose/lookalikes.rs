//! Look-alikes: two explanations the data supports about equally, and the experiment that
//! tells them apart.
//!
//! Some effects leave nearly the same residual on a given log: a constant load and a friction
//! that differs by direction on a run at equal speeds both ways, load friction and dead time
//! on a run that never brakes. Forward selection keeps the one that explains more, but when
//! the other was also significant and explained at least [`CLOSE`] of as much, `diagnose`
//! says so and names an experiment in which they differ.
//!
//! Two look-alikes can also both enter forward selection: the runner-up still explains a
//! significant part of what is left after the leader. They are reported as a pair too (not
//! as two independent findings) when, besides the shares being close, the leader already
//! explains at least `1 − CLOSE` of what the runner-up explains alone: its share beyond the
//! leader is at most [`CLOSE`] of its share alone. Two independent effects keep their whole
//! share when the other enters, however close their sizes.
use super::{carriers::Carrier, Finding, Tested};
use crate::effects;
use serde::Serialize;

/// Ratio of explained shares above which two significant explanations count as look-alikes:
/// the runner-up explains at least two thirds of what the leader explains.
pub const CLOSE: f64 = 2.0 / 3.0;

/// Two explanations the data cannot tell apart, and how to tell them apart.
#[derive(Debug, Clone, Serialize)]
pub struct LookAlike {
    /// The kept explanation first, then the look-alike (effect names or carrier variables).
    pub names: [String; 2],
    /// Shares of the residual each explains on its own.
    pub shares: [f64; 2],
    /// An experiment (a log to record or simulate) in which the two differ.
    pub experiment: String,
    /// True when both entered forward selection (both are findings): the runner-up's share
    /// beyond the leader is then what the data tells apart, the rest they share.
    pub both_found: bool,
}

/// The experiment that separates two effects or carriers (order does not matter): the
/// registry's table ([`effects::LOOK_ALIKES`]), else a log that excites each on its own.
pub fn experiment(a: &str, b: &str) -> String {
    effects::experiment(a, b)
        .unwrap_or(
            "a log that excites one and not the other: steady speeds, slow reversals and braking steps, each on its own",
        )
        .to_string()
}

/// Look-alikes of the kept findings among the effects tested beside them (first round),
/// and among the carriers.
pub fn find(
    findings: &[Finding],
    tested: &[Tested],
    carriers: &[Carrier],
    alpha_per_test: f64,
) -> Vec<LookAlike> {
    let mut out = found_pairs(findings, tested);
    for f in findings {
        let Some(first) = tested.iter().find(|t| t.name == f.name && t.kept) else {
            continue;
        };
        for t in tested {
            if t.kept
                || t.name == f.name
                || t.equation != first.equation
                || t.p_value >= alpha_per_test
                || t.explained < CLOSE * first.explained
            {
                continue;
            }
            if out
                .iter()
                .any(|l: &LookAlike| l.names.contains(&t.name) && l.names.contains(&f.name))
            {
                continue;
            }
            out.push(LookAlike {
                names: [f.name.clone(), t.name.clone()],
                shares: [first.explained, t.explained],
                experiment: experiment(&f.name, &t.name),
                both_found: false,
            });
        }
    }
    // On the moving windows the torque equation keeps, a Coulomb friction that differs by
    // direction (`dc·|sgn ω|`) is the constant column itself: an offset found there is always
    // also that asymmetry, whatever the shares say.
    if let Some(f) = findings.iter().find(|f| f.name == "offset") {
        if !out.iter().any(|l| {
            l.names.iter().any(|n| n == "asymmetry") && l.names.iter().any(|n| n == "offset")
        }) {
            out.push(LookAlike {
                names: ["offset".to_string(), "asymmetry".to_string()],
                shares: [f.score, f.score],
                experiment: experiment("offset", "asymmetry"),
                both_found: false,
            });
        }
    }
    if let [a, b, ..] = carriers {
        if b.share >= CLOSE * a.share {
            out.push(LookAlike {
                names: [a.variable.to_string(), b.variable.to_string()],
                shares: [a.share, b.share],
                experiment: experiment(a.variable, b.variable),
                both_found: false,
            });
        }
    }
    out
}

/// Pairs of findings of one equation that both entered forward selection and look alike:
/// the runner-up explains alone at least [`CLOSE`] of what the leader explains alone, and at
/// most [`CLOSE`] of its own share is left once the leader is in (see the module doc). The
/// shares are each one's own against the base (the first round of selection).
fn found_pairs(findings: &[Finding], tested: &[Tested]) -> Vec<LookAlike> {
    let alone = |f: &Finding| {
        tested
            .iter()
            .find(|t| t.name == f.name && t.equation == f.equation && t.kept)
            .map(|t| t.explained)
    };
    let mut out = Vec::new();
    for (k, a) in findings.iter().enumerate() {
        for b in &findings[k + 1..] {
            if a.equation != b.equation {
                continue;
            }
            let (Some(sa), Some(sb)) = (alone(a), alone(b)) else {
                continue;
            };
            // The leader explains more alone; the runner-up's finding score is its share
            // beyond the findings that entered before it (the leader among them).
            let (lead, run, s_lead, s_run) = if sa >= sb {
                (a, b, sa, sb)
            } else {
                (b, a, sb, sa)
            };
            let beyond = run.score;
            if s_lead > 0.0 && s_run >= CLOSE * s_lead && beyond <= CLOSE * s_run {
                out.push(LookAlike {
                    names: [lead.name.clone(), run.name.clone()],
                    shares: [s_lead, s_run],
                    experiment: experiment(&lead.name, &run.name),
                    both_found: true,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::Equation;

    fn finding(name: &str, score: f64) -> Finding {
        Finding {
            name: name.into(),
            spec: name.into(),
            score,
            explanation: String::new(),
            equation: Equation::Mechanical,
            p_value: 1e-9,
            t2: 1.0,
            delta_bic: -10.0,
            kind: None,
        }
    }

    fn tested(name: &str, explained: f64) -> Tested {
        Tested {
            name: name.into(),
            equation: Equation::Mechanical,
            spec: name.into(),
            explained,
            p_value: 1e-9,
            kept: true,
        }
    }

    /// Two findings that share what they explain are one look-alike pair with the experiment
    /// that separates them; two that explain different parts of the residual are not.
    #[test]
    fn two_findings_that_share_the_residual_are_a_pair() {
        // Compliance alone 0.27, backlash alone 0.25 but only 0.12 beyond compliance.
        let shared = find(
            &[finding("compliance", 0.27), finding("backlash", 0.12)],
            &[tested("compliance", 0.27), tested("backlash", 0.25)],
            &[],
            1e-4,
        );
        assert_eq!(shared.len(), 1, "{shared:?}");
        assert!(shared[0].both_found);
        assert_eq!(shared[0].names, ["compliance", "backlash"]);
        assert_eq!(shared[0].experiment, experiment("backlash", "compliance"));
        // An offset and a position load of similar size, each keeping its share.
        let apart = find(
            &[finding("offset", 0.30), finding("position_load", 0.25)],
            &[tested("offset", 0.30), tested("position_load", 0.26)],
            &[],
            1e-4,
        );
        assert!(apart.iter().all(|l| !l.both_found), "{apart:?}");
    }

    #[test]
    fn every_named_pair_has_its_own_experiment_in_either_order() {
        for (a, b) in [
            ("offset", "asymmetry"),
            ("load_friction", "deadtime"),
            ("reversal", "frequency"),
            ("acceleration", "current"),
            ("backlash", "compliance"),
        ] {
            assert_eq!(experiment(a, b), experiment(b, a));
            assert!(!experiment(a, b).starts_with("a log that excites"));
        }
        assert!(experiment("cogging", "offset").starts_with("a log that excites"));
    }
}
