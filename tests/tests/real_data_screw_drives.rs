//! TRO2021 screw drives (../shared/data/TRO2021_screw_drives): the static friction curves and
//! the Stribeck significance test against the authors' parameters (strbVelocity 6.4, 0, 0.688
//! for drives 1, 2, 3).
use e2e::shared_data;
use xtask::real_data::screw_drives;
use xtask::real_data::static_curve::Term;

#[test]
fn stribeck_where_the_authors_have_it_and_not_on_drive_2() {
    let Some(data) = shared_data("stribeck_where_the_authors_have_it_and_not_on_drive_2") else {
        return;
    };
    let d1 = screw_drives::analyse(&data, 1).unwrap();
    let d2 = screw_drives::analyse(&data, 2).unwrap();
    let d3 = screw_drives::analyse(&data, 3).unwrap();
    // Drive 1 (lead screw): Stribeck selected by the F-test, its velocity of the order of the
    // authors' 6.4 (this data gives ≈ 3.5 rad/s): within the decade around it, since their
    // curve comes from another fit of the same points.
    assert!(
        d1.selection.has(Term::Stribeck),
        "{:?}",
        d1.selection.chosen.terms
    );
    let vs = d1.selection.chosen.vs.unwrap();
    assert!((1.0..10.0).contains(&vs), "drive 1 vs = {vs}");
    // Drive 2 (anti-backlash, authors: 0): no Stribeck, in neither direction.
    assert!(!d2.selection.has(Term::Stribeck));
    for o in &d2.one_sided {
        assert!(
            o.p.is_none_or(|p| p > 0.01),
            "drive 2, direction {}: p = {:?}",
            o.sign,
            o.p
        );
    }
    // Drive 3 (worm, authors: 0.688): the drop of friction at low speed shows in one direction
    // (v > 0 as recorded) with a Stribeck velocity below 2 rad/s; a symmetric Stribeck term
    // does not pass at 1 % because the other direction has none. Where a drop is claimed,
    // p < 1e-4, a hundred times below the 1 % level: present, not marginal.
    let pos = &d3.one_sided[0];
    assert!(pos.p.unwrap() < 1e-4, "drive 3 v>0: p = {:?}", pos.p);
    assert!(pos.vs.unwrap() < 2.0, "drive 3 v>0: vs = {:?}", pos.vs);
    // In the other direction (v < 0 as recorded) friction does not fall with speed: the
    // authors' symmetric Stribeck term (one strbVelocity for both directions) is not in the
    // data there.
    let neg = &d3.one_sided[1];
    assert!(
        neg.p.is_none_or(|p| p > 0.01),
        "drive 3 v<0: p = {:?}",
        neg.p
    );
    // Drive 1 (authors: 6.4 rad/s) has it in both directions.
    for o in &d1.one_sided {
        assert!(
            o.p.is_some_and(|p| p < 1e-4),
            "drive 1, direction {}: p = {:?}",
            o.sign,
            o.p
        );
    }
    // Every drive has Coulomb friction far above its viscous part at 1 rad/s.
    for d in [&d1, &d2, &d3] {
        let c = &d.selection.chosen;
        assert!(c.get(Term::Coulomb).unwrap() > 10.0 * c.get(Term::Viscous).unwrap());
    }
}

#[test]
fn each_set_point_becomes_one_point() {
    let Some(data) = shared_data("each_set_point_becomes_one_point") else {
        return;
    };
    // ../shared/data/README.md: 32, 30 and 46 set-points of 500 samples.
    for (k, n) in [(1, 32), (2, 30), (3, 46)] {
        let pts = screw_drives::read_points(&screw_drives::path(&data, k)).unwrap();
        assert_eq!(pts.len(), n, "drive {k}");
        assert!(pts.iter().all(|p| p.samples == 450));
        // Torque and velocity keep the same sign (friction opposes motion).
        assert!(pts
            .iter()
            .filter(|p| p.v.abs() > 0.5)
            .all(|p| p.v * p.tau > 0.0 || p.v.abs() < 1.0));
    }
}
