use super::*;
use crate::approx::mls::Order;
use crate::geometry::Shape;
use crate::solid::fracture::tests::params;
use crate::solid::fracture::{Discontinuity, FractureParams, Notch};
use crate::solid::{ElasticSolid, Obstacles};

/// A 1 m x 0.3 m bar whose halves move apart at `speed` and spin at
/// `spin` rad/s, resampling by `rule`, with a notch of half-length 0.1 m
/// across its middle.
fn notched_bar(
    rule: Resampling,
    discontinuity: Discontinuity,
    speed: Real,
    spin: Real,
) -> ElasticSolid {
    let mut fracture = FractureParams::brittle(2e4);
    fracture.discontinuity = discontinuity;
    fracture.resample = Some(rule);
    let p = params(2, Some(fracture));
    let shape = Shape::Box {
        half_extents: Vector::new(0.5, 0.15, 0.0),
    };
    let rest = shape.sample_volume(p.spacing, 2).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(speed * x.x.signum() - spin * x.y, spin * x.x, 0.0))
        .collect();
    let n = rest.len();
    let mut solid = ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default())
        .expect("solid");
    solid
        .notch(&[Notch {
            center: Vector::new(0.01, 0.0, 0.0),
            normal: Vector::x(),
            radius: 0.1,
        }])
        .expect("a notch that fits");
    solid
}

/// Mass, linear momentum and angular momentum about the origin.
fn totals(solid: &ElasticSolid) -> (Real, Vector, Vector) {
    let mut mass = 0.0;
    let mut momentum = Vector::zeros();
    let mut angular = Vector::zeros();
    for ((x, v), m) in solid
        .positions
        .iter()
        .zip(&solid.velocities)
        .zip(solid.masses())
    {
        mass += m;
        momentum += v * *m;
        angular += x.cross(&(v * *m));
    }
    (mass, momentum, angular)
}

#[test]
fn the_particles_beside_a_notch_split_keeping_mass_momentum_and_ids() {
    for discontinuity in [
        Discontinuity::Visibility,
        Discontinuity::Transparency { kappa: 1.0 },
    ] {
        let mut solid = notched_bar(Resampling::new(), discontinuity, 0.5, 2.0);
        let n = solid.len();
        let before = (solid.positions.clone(), solid.rest.clone());
        let (mass, momentum, angular) = totals(&solid);
        let done = solid.resample().expect("within the capacity");
        assert!(done.split > 0 && done.added >= 2 * done.split, "{done:?}");
        assert_eq!(solid.len(), n + done.added as usize);
        // Every particle keeps its index; the new ones follow.
        assert_eq!(solid.positions[..n], before.0[..]);
        assert_eq!(solid.rest[..n], before.1[..]);
        // Only particles beside the notch split: within a support of it.
        let radii = solid.radii().expect("radii of their own");
        for (i, x) in solid.rest[..n].iter().enumerate() {
            if radii[i] < 0.1 {
                assert!(
                    (x.x - 0.01).abs() < 0.1 && x.y.abs() < 0.2,
                    "particle {i} at {x:?} split far from the notch"
                );
            }
        }
        let (mass2, momentum2, angular2) = totals(&solid);
        assert!((mass2 - mass).abs() <= 1e-14 * mass, "{mass} -> {mass2}");
        assert!(
            (momentum2 - momentum).norm() <= 1e-12 * mass,
            "{momentum} -> {momentum2}"
        );
        assert!(
            (angular2 - angular).norm() <= 1e-12 * mass,
            "{angular} -> {angular2}"
        );
        // New particles sit on their parent's side of the notch, in its
        // fragment, and inside the bar.
        let fracture = solid.fracture().expect("fractures");
        assert_eq!(fracture.fragments().len(), solid.len());
        for x in &solid.rest[n..] {
            assert!(
                (x.x - 0.01).abs() > 1e-9 && x.x.abs() < 0.5 && x.y.abs() < 0.15,
                "{x:?}"
            );
        }
        // What Eq. 71 asked is met, or the particle is at its smallest.
        let (q, count) = solid.sampling();
        let rule = Resampling::new();
        for i in 0..solid.len() {
            let short = q[i] < rule.q_min.min(count[i]) - 1e-9;
            let smallest =
                solid.support_radius(i) / (3.0 as Real).sqrt() < rule.min_radius_ratio * 0.1;
            assert!(
                !short || smallest,
                "particle {i}: Q = {} of {}",
                q[i],
                count[i]
            );
        }
        // Nothing more to split until the cracks move.
        assert_eq!(solid.resample().expect("fits").added, 0);
        // The smallest particle sets the explicit step.
        let wave = solid.params.stable_dt(0.5);
        assert!(
            solid.stable_dt(0.5) < 0.6 * wave,
            "{} vs {wave}",
            solid.stable_dt(0.5)
        );
    }
}

#[test]
fn with_radii_of_their_own_the_particles_reproduce_linear_fields() {
    let mut solid = notched_bar(Resampling::new(), Discontinuity::Visibility, 0.0, 0.0);
    solid.resample().expect("fits");
    let a = nalgebra::Matrix3::new(0.3, -0.2, 0.0, 0.1, 0.4, 0.0, 0.0, 0.0, 0.0);
    let u: Vec<Vector> = solid.rest.iter().map(|x| a * x).collect();
    let t = &solid.topology;
    let mut checked = 0;
    for i in 0..solid.len() {
        if t.gradients.orders()[i] != Order::Linear {
            continue;
        }
        let g = t.gradients.vector_gradient(i, &u);
        assert!((g - a).norm() < 1e-10, "particle {i}: {g} vs {a}");
        checked += 1;
    }
    assert!(
        checked > solid.len() * 9 / 10,
        "{checked} of {}",
        solid.len()
    );
    // A pair interacts within its mean radius: the pair weights of every
    // split particle sum to one over fewer, nearer neighbours.
    let radii = solid.radii().expect("radii");
    let edges = t.gradients.neighbour_indices();
    for i in 0..solid.len() {
        for e in t.gradients.range(i) {
            let j = edges[e] as usize;
            let r = t.rest_offset[e].norm();
            assert!(r < 0.5 * (radii[i] + radii[j]), "pair {i}-{j} at {r}");
        }
    }
}

#[test]
fn a_resampled_solid_steps_and_continues_from_its_snapshot_bit_for_bit() {
    let mut solid = notched_bar(
        Resampling::new(),
        Discontinuity::Transparency { kappa: 1.0 },
        1.0,
        0.0,
    );
    let built = solid.clone();
    let mut added = 0;
    for _ in 0..40 {
        added += solid.resample().expect("fits").added;
        solid.step(2e-4, &Vector::zeros(), 100);
        solid.fracture_step().expect("bounded");
    }
    assert!(added > 0);
    let snapshot = solid.snapshot();
    assert_eq!(snapshot.radii.as_ref().map(Vec::len), Some(solid.len()));
    // Into the solid as built: it grows to the snapshot's particles.
    let mut restored = built.clone();
    restored
        .restore_snapshot(&snapshot)
        .expect("a snapshot of this solid");
    assert_eq!(restored.len(), solid.len());
    for _ in 0..20 {
        for s in [&mut solid, &mut restored] {
            s.resample().expect("fits");
            s.step(2e-4, &Vector::zeros(), 100);
            s.fracture_step().expect("bounded");
        }
    }
    assert_eq!(restored.positions, solid.positions);
    assert_eq!(restored.velocities, solid.velocities);
    assert_eq!(restored.fracture(), solid.fracture());
    // And back: the built state restores into the grown solid.
    let mut shrunk = solid.clone();
    shrunk
        .restore_snapshot(&built.snapshot())
        .expect("the built state");
    assert_eq!(shrunk.len(), built.len());
    assert!(shrunk.radii().is_none());
    assert_eq!(shrunk.fracture(), built.fracture());

    // A forged snapshot is refused, the solid unchanged: radii past the
    // support, more particles than the capacity.
    let mut forged = snapshot.clone();
    if let Some(r) = forged.radii.as_mut() {
        r[0] = 1.0;
    }
    let mut target = built.clone();
    assert!(target.restore_snapshot(&forged).is_err());
    assert_eq!(target.len(), built.len());
    let mut forged = snapshot;
    let extra = built.capacity() + 1 - forged.positions.len();
    forged
        .positions
        .extend(std::iter::repeat_n(Vector::zeros(), extra));
    assert!(target.restore_snapshot(&forged).is_err());
    assert_eq!(target.positions, built.positions);
}

#[test]
fn growth_past_the_capacity_is_refused_leaving_the_solid_as_it_was() {
    let rule = Resampling {
        max_particles: Some(1),
        ..Resampling::new()
    };
    let mut solid = notched_bar(rule, Discontinuity::Visibility, 0.0, 0.0);
    // Never below the particles built.
    assert_eq!(solid.capacity(), solid.len());
    let before = solid.clone();
    let Err(ResampleError::ParticleLimit { count, limit }) = solid.resample() else {
        panic!("grew past its capacity");
    };
    assert!(count > limit && limit == before.len());
    assert_eq!(solid.positions, before.positions);
    assert_eq!(solid.fracture(), before.fracture());
    assert!(solid.radii().is_none());
}

#[test]
fn a_smaller_minimal_radius_splits_more_and_out_of_range_knobs_are_refused() {
    let count = |ratio| {
        let rule = Resampling {
            min_radius_ratio: ratio,
            ..Resampling::new()
        };
        let mut solid = notched_bar(rule, Discontinuity::Visibility, 0.0, 0.0);
        solid.resample().expect("fits").added
    };
    let (coarse, fine) = (count(0.9), count(0.3));
    // At 0.9 no particle may split even once (three parts need 0.58).
    assert_eq!(coarse, 0);
    assert!(fine > count(0.5), "{fine}");

    for (rule, what) in [
        (
            Resampling {
                q_min: 0.5,
                ..Resampling::new()
            },
            "resample.q_min",
        ),
        (
            Resampling {
                q_min: Real::NAN,
                ..Resampling::new()
            },
            "resample.q_min",
        ),
        (
            Resampling {
                min_radius_ratio: 1.0,
                ..Resampling::new()
            },
            "resample.min_radius_ratio",
        ),
        (
            Resampling {
                min_radius_ratio: 0.0,
                ..Resampling::new()
            },
            "resample.min_radius_ratio",
        ),
    ] {
        let mut p = FractureParams::brittle(1e4);
        p.resample = Some(rule);
        let error = p.validate(0.05, false, false).expect_err("out of range");
        assert!(error.to_string().contains(what), "{error}");
    }
}

#[test]
fn in_3d_the_particles_beside_a_penny_notch_split_in_opposite_pairs_around_them() {
    let mut fracture = FractureParams::brittle(2e4);
    fracture.discontinuity = Discontinuity::Visibility;
    // A 3D particle holds 26 neighbours at a support of two spacings, and
    // a notch beside it hides about nine: Pauly's 10 would split none.
    fracture.resample = Some(Resampling {
        q_min: 25.0,
        ..Resampling::new()
    });
    let p = params(3, Some(fracture));
    let shape = Shape::Box {
        half_extents: Vector::new(0.25, 0.15, 0.15),
    };
    let rest = shape.sample_volume(p.spacing, 3).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(0.3 * x.x.signum(), 0.0, 0.0) + Vector::new(0.0, -x.z, x.y))
        .collect();
    let n = rest.len();
    let mut solid = ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default())
        .expect("solid");
    solid
        .notch(&[Notch {
            center: Vector::new(0.01, 0.0, 0.0),
            normal: Vector::x(),
            radius: 0.08,
        }])
        .expect("a notch that fits");
    let (mass, momentum, angular) = totals(&solid);
    let done = solid.resample().expect("within the capacity");
    assert!(done.split > 0, "{done:?}");
    // Seven parts at most (a radius of 0.52 h), an even number added.
    assert!(
        done.added <= 6 * done.split && done.added.is_multiple_of(2),
        "{done:?}"
    );
    let (mass2, momentum2, angular2) = totals(&solid);
    assert!((mass2 - mass).abs() <= 1e-14 * mass);
    assert!((momentum2 - momentum).norm() <= 1e-12 * mass);
    assert!((angular2 - angular).norm() <= 1e-12 * mass);
    // Off the notch's plane, and never smaller than the smallest radius.
    let radii = solid.radii().expect("radii");
    for x in &solid.rest[n..] {
        assert!(
            (x.x - 0.01).abs() > 1e-9,
            "a new particle on the notch's plane"
        );
    }
    assert!(radii[n..].iter().all(|r| (0.5 * 0.1..0.1).contains(r)));
    // Linear fields reproduced by every particle that kept its order.
    let a = nalgebra::Matrix3::new(0.3, -0.2, 0.1, 0.1, 0.4, -0.3, 0.2, 0.0, 0.1);
    let u: Vec<Vector> = solid.rest.iter().map(|x| a * x).collect();
    let t = &solid.topology;
    for i in 0..solid.len() {
        if t.gradients.orders()[i] == Order::Linear {
            let g = t.gradients.vector_gradient(i, &u);
            assert!((g - a).norm() < 1e-10, "particle {i}: {g}");
        }
    }
    assert_eq!(solid.resample().expect("fits").added, 0);
}
