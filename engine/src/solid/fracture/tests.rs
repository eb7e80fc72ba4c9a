use super::crack::segment_triangle;
use super::*;
use crate::approx::KernelKind;
use crate::approx::mls::Order;
use crate::geometry::Shape;
use crate::solid::{ElasticSolid, Integrator, Material, Obstacles, SolidParams};

/// The fracturing solids' test material: 5 cm spacing, a support of two
/// spacings, E = 1 MPa, explicit.
pub(in crate::solid) fn params(dim: usize, fracture: Option<FractureParams>) -> SolidParams {
    let young = 1e6;
    SolidParams {
        dim,
        spacing: 0.05,
        density: 1000.0,
        young,
        material: Material::from_young_poisson(young, 0.3, 0.0),
        order: Order::Linear,
        support: 0.1,
        hourglass: 0.1,
        damping: 0.0,
        friction: 0.0,
        integrator: Integrator::Explicit { cfl: 0.5 },
        plasticity: None,
        fracture,
    }
}

/// A 2D bar of 1 m x 0.3 m whose halves are pulled apart at `speed`.
fn pulled_bar(fracture: Option<FractureParams>, speed: Real) -> ElasticSolid {
    let p = params(2, fracture);
    let shape = Shape::Box {
        half_extents: Vector::new(0.5, 0.15, 0.0),
    };
    let rest = shape.sample_volume(p.spacing, 2).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(speed * x.x.signum(), 0.0, 0.0))
        .collect();
    let n = rest.len();
    ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default()).expect("solid")
}

fn run(solid: &mut ElasticSolid, steps: usize) -> u32 {
    let mut started = 0;
    for _ in 0..steps {
        solid.step(2e-4, &Vector::zeros(), 100);
        started += solid.fracture_step().expect("bounded").started;
    }
    started
}

fn momentum(solid: &ElasticSolid) -> Vector {
    solid
        .velocities
        .iter()
        .zip(solid.masses())
        .map(|(v, m)| v * *m)
        .sum()
}

#[test]
fn eq70_leaves_the_weight_at_the_front_and_removes_it_behind() {
    let kernel = KernelKind::Poly6;
    let t = Discontinuity::Transparency { kappa: 1.0 };
    let q = 0.5;
    let plain = transparent_weight(kernel, q, 0.0).expect("inside");
    // At the front the crossing adds nothing: the shape functions stay
    // continuous around the tip.
    assert_eq!(
        transparent_weight(kernel, q, opacity(t, 0.0, 0.1)),
        Some(plain)
    );
    // Behind it the weight falls monotonically ...
    let mut last = plain;
    for k in 1..7 {
        let w = transparent_weight(kernel, q, opacity(t, 0.01 * k as Real, 0.1)).unwrap_or(0.0);
        assert!(w < last, "not falling at d_s = {}", 0.01 * k as Real);
        last = w;
    }
    // ... as W(q + (d_s / (kappa s))^2): gone once q + (d_s/s)^2 >= 1.
    let edge = (1.0 - q).sqrt() * 0.1;
    assert!(transparent_weight(kernel, q, opacity(t, edge * 1.0001, 0.1)).is_none());
    let just = transparent_weight(kernel, q, opacity(t, edge * 0.99, 0.1)).expect("inside");
    let expected = (1.0 - (q + 0.99 * 0.99 * (1.0 - q)).powi(2)).powi(3);
    assert!((just - expected).abs() < 1e-12, "{just} vs {expected}");
    // Visibility: any crossing removes the pair.
    assert!(transparent_weight(kernel, q, opacity(Discontinuity::Visibility, 0.0, 0.1)).is_none());
}

#[test]
fn eq71_counts_the_neighbours_without_cracks_and_fewer_with() {
    let kernel = KernelKind::Poly6;
    let pairs = [(0.3, 0.0), (0.5, 0.0), (0.9, 0.0)];
    assert!((undersampling(kernel, pairs.into_iter()) - 3.0).abs() < 1e-12);
    let cut = [(0.3, 0.0), (0.5, 0.2), (0.9, Real::INFINITY)];
    let q = undersampling(kernel, cut.into_iter());
    assert!(q > 1.0 && q < 2.0, "{q}");
}

#[test]
fn segments_cross_triangles_inside_only() {
    let [p, q, r] = [Vector::zeros(), Vector::x(), Vector::y()];
    let hit = |a: [Real; 3], b: [Real; 3]| {
        segment_triangle(&Vector::from(a), &Vector::from(b), &p, &q, &r)
    };
    assert_eq!(
        hit([0.2, 0.2, -1.0], [0.2, 0.2, 1.0]),
        Some(Vector::new(0.2, 0.2, 0.0))
    );
    // Outside the triangle, parallel to it, short of it, or ending on it.
    assert!(hit([0.8, 0.8, -1.0], [0.8, 0.8, 1.0]).is_none());
    assert!(hit([0.1, 0.1, 0.5], [0.3, 0.1, 0.5]).is_none());
    assert!(hit([0.2, 0.2, 0.5], [0.2, 0.2, 1.0]).is_none());
    assert!(hit([0.2, 0.2, 0.0], [0.2, 0.2, 1.0]).is_none());
}

#[test]
fn a_2d_crack_cuts_the_segments_across_it_and_measures_its_front() {
    // A vertical crack from y = -0.1 to 0.1 at x = 0.
    let crack = Crack::start(2, Vector::zeros(), Vector::x(), 0.1, 0.2);
    let across = crack.crossing(
        &Vector::new(-0.05, 0.02, 0.0),
        &Vector::new(0.05, 0.02, 0.0),
    );
    let across = across.expect("crosses");
    assert!((across.at - Vector::new(0.0, 0.02, 0.0)).norm() < 1e-12);
    assert!(
        (across.to_front - 0.08).abs() < 1e-12,
        "{}",
        across.to_front
    );
    assert!(
        crack
            .crossing(
                &Vector::new(-0.05, 0.15, 0.0),
                &Vector::new(0.05, 0.15, 0.0)
            )
            .is_none()
    );
    assert!(
        crack
            .crossing(
                &Vector::new(0.01, -0.05, 0.0),
                &Vector::new(0.01, 0.05, 0.0)
            )
            .is_none()
    );
    // Advancing the upper tip by 0.1 extends the cut and moves its front.
    let mut crack = crack;
    let moves: Vec<_> = crack
        .front()
        .iter()
        .map(|f| (f.heading.y > 0.0).then_some((f.at + f.heading * 0.1, f.heading)))
        .collect();
    crack.advance(&moves, 1.0);
    let above = crack.crossing(
        &Vector::new(-0.05, 0.15, 0.0),
        &Vector::new(0.05, 0.15, 0.0),
    );
    assert!((above.expect("now crosses").to_front - 0.05).abs() < 1e-12);
}

#[test]
fn a_3d_crack_starts_as_a_disc_and_grows_its_rim() {
    let mut crack = Crack::start(3, Vector::zeros(), Vector::z(), 0.1, 0.0);
    assert_eq!(crack.front().len(), 6);
    let through =
        |c: &Crack, x: Real| c.crossing(&Vector::new(x, 0.0, -0.05), &Vector::new(x, 0.0, 0.05));
    assert!(through(&crack, 0.02).is_some());
    assert!(through(&crack, 0.15).is_none());
    // Every rim node runs outward by 0.1: the rim (now 0.2 from the
    // centre, six edges of 0.2) splits, and the disc cuts out to 0.2.
    let moves: Vec<_> = crack
        .front()
        .iter()
        .map(|f| Some((f.at + f.heading * 0.1, f.heading)))
        .collect();
    crack.advance(&moves, 0.15);
    assert_eq!(crack.front().len(), 12);
    assert!(through(&crack, 0.15).is_some());
    assert!(through(&crack, 0.25).is_none());
    let front = crack.distance_to_front(&Vector::zeros());
    assert!(front > 0.17 && front <= 0.2, "{front}");
}

/// Steps `solid` `steps` times (0.2 ms each) and checks its momentum
/// held; returns it, how many fronts branched, and each new arm as it was
/// when it branched.
fn branching_run(mut solid: ElasticSolid, steps: usize) -> (ElasticSolid, u32, Vec<Crack>) {
    let before = momentum(&solid);
    let (mut branched, mut arms) = (0, Vec::new());
    for _ in 0..steps {
        solid.step(2e-4, &Vector::zeros(), 100);
        // Before the step's fracture update.
        let cracks = solid.fracture().expect("it fractures").cracks().len();
        let step = solid.fracture_step().expect("bounded");
        branched += step.branched;
        if step.branched > 0 {
            // The update appends the new arms first, then the cracks it
            // started; each arm leaves a point where its parent's front
            // just was.
            let f = solid.fracture().expect("it fractures");
            arms.extend(
                f.cracks()[cracks..cracks + step.branched as usize]
                    .iter()
                    .cloned(),
            );
        }
    }
    let drift = (momentum(&solid) - before).norm();
    let scale: Real = solid.masses().iter().sum::<Real>() * 0.5;
    assert!(drift < 1e-10 * scale, "momentum drift {drift:e}");
    (solid, branched, arms)
}

/// A 3D branch, built directly: its disc passes through the front node,
/// its arm leaves 15° to one side of the heading (turned about the
/// front's tangent, towards the opening direction) while the front turns
/// 15° to the other, and the half of its rim behind its centre is no
/// front.
#[test]
fn a_3d_branch_is_a_disc_tilted_about_the_fronts_tangent() {
    let at = Vector::new(0.3, -0.2, 0.1);
    let (heading, normal, step) = (Vector::x(), Vector::y(), 0.02);
    let (branch, turned) = Crack::branch(3, at, heading, normal, step, 0.0).expect("a branch");
    let angle = FractureParams::BRANCH_ANGLE;
    assert!((turned - Vector::new(angle.cos(), -angle.sin(), 0.0)).norm() < 1e-15);
    let arm = Vector::new(angle.cos(), angle.sin(), 0.0);
    let plane = arm.cross(&Vector::z());
    let front = branch.front();
    assert_eq!(front.len(), 6);
    assert!(
        (front[0].at - at).norm() < 1e-15,
        "the junction is at the tip"
    );
    for node in front {
        // On the disc of diameter `step` through `at`, in the plane of
        // the arm and the tangent.
        let center = at + arm * (0.5 * step);
        assert!(((node.at - center).norm() - 0.5 * step).abs() < 1e-15);
        assert!((node.at - at).dot(&plane).abs() < 1e-15);
        assert!(node.heading.dot(&plane).abs() < 1e-15);
        let ahead = (node.at - center).dot(&arm) >= 0.0;
        assert_eq!(node.active, ahead, "{node:?}");
    }
    assert_eq!(front.iter().filter(|n| n.active).count(), 3);
    // A segment along the arm, past the junction, crosses nothing; one
    // across the disc's plane through its middle crosses it.
    let middle = at + arm * (0.5 * step);
    assert!(
        branch
            .crossing(&(middle - plane * 0.01), &(middle + plane * 0.01))
            .is_some()
    );
    // No tangent where the opening direction is the heading.
    assert!(Crack::branch(3, at, heading, heading, step, 0.0).is_none());
}

/// Branching in 3D: a block pulled apart past its branching stress
/// leaves tilted discs from its fronts, each starting at a vertex of its
/// parent; without branching, or at 10⁹, none; momentum kept.
#[test]
fn a_3d_front_past_its_branching_stress_leaves_tilted_discs() {
    let run_with = |branching: Option<Real>| {
        let mut fracture = FractureParams::brittle(2e4);
        fracture.branching = branching;
        branching_run(pulled_block(fracture), 200)
    };
    let (_, plain, _) = run_with(None);
    assert_eq!(plain, 0);
    let (_, never, _) = run_with(Some(1e9));
    assert_eq!(never, 0, "a front branched below its branching stress");

    let (block, branched, arms) = run_with(Some(1.0));
    assert!(branched > 0, "no front branched");
    assert_eq!(arms.len(), branched as usize);
    let fracture = block.fracture().expect("it fractures");
    for arm in &arms {
        // Its junction, the first rim node, lies on a vertex of another
        // crack (its parent's front when it branched), and is no front.
        let junction = &arm.front()[0];
        assert!(!junction.active);
        let on_parent = fracture
            .cracks()
            .iter()
            // Not the arm itself, grown since (vertices are only added).
            .filter(|c| !c.vertices().starts_with(arm.vertices()))
            .any(|c| c.distance_to_vertices(&junction.at) < 1e-12);
        assert!(
            on_parent,
            "a branch whose junction {:?} is on no crack",
            junction.at
        );
    }
    assert!(fracture.cracks().len() <= FractureParams::DEFAULT_MAX_CRACKS as usize);
    let (mesh, _) = block.crack_surface().expect("cracks have faces");
    assert!(
        mesh.vertices
            .iter()
            .all(|v| v.iter().all(|x| x.is_finite()))
    );
}

#[test]
fn cutting_the_last_pair_between_two_parts_splits_off_the_smaller() {
    // A chain 0-1-2-3-4 with a side branch 1-5; cut 3-4, then 1-2.
    let mut pairs = vec![(0usize, 1usize), (1, 2), (2, 3), (3, 4), (1, 5), (0, 5)];
    let neighbours = |pairs: &Vec<(usize, usize)>, i: usize| -> Vec<usize> {
        pairs
            .iter()
            .filter_map(|&(a, b)| {
                if a == i {
                    Some(b)
                } else if b == i {
                    Some(a)
                } else {
                    None
                }
            })
            .collect()
    };
    let (mut labels, mut count) = label(6, |i| neighbours(&pairs, i).into_iter());
    assert_eq!((count, labels.clone()), (1, vec![0; 6]));
    // Cutting 0-5 leaves 5 joined through 1: nothing splits.
    pairs.retain(|&p| p != (0, 5));
    split(
        0,
        5,
        |i| neighbours(&pairs, i).into_iter(),
        &mut labels,
        &mut count,
    );
    assert_eq!(count, 1);
    pairs.retain(|&p| p != (3, 4));
    split(
        3,
        4,
        |i| neighbours(&pairs, i).into_iter(),
        &mut labels,
        &mut count,
    );
    assert_eq!((count, labels.clone()), (2, vec![0, 0, 0, 0, 1, 0]));
    pairs.retain(|&p| p != (1, 2));
    split(
        1,
        2,
        |i| neighbours(&pairs, i).into_iter(),
        &mut labels,
        &mut count,
    );
    assert_eq!((count, labels), (3, vec![0, 0, 2, 2, 1, 0]));
}

#[test]
fn fragments_are_connected_sets_numbered_by_their_lowest_particle() {
    // 0-3 and 1-4 joined, 2 alone.
    let pairs = [(0usize, 3usize), (1, 4)];
    let (labels, count) = label(5, |i| {
        pairs.iter().filter_map(move |&(a, b)| {
            if a == i {
                Some(b)
            } else if b == i {
                Some(a)
            } else {
                None
            }
        })
    });
    assert_eq!(count, 3);
    assert_eq!(labels, vec![0, 1, 2, 0, 1]);
}

use super::fragments::{label, split};

#[test]
fn below_its_strength_a_fracturing_solid_moves_as_an_elastic_one_bit_for_bit() {
    let mut plain = pulled_bar(None, 0.05);
    let mut strong = pulled_bar(Some(FractureParams::brittle(1e9)), 0.05);
    assert_eq!(run(&mut strong, 40), 0);
    for _ in 0..40 {
        plain.step(2e-4, &Vector::zeros(), 100);
    }
    assert_eq!(plain.positions, strong.positions);
    assert_eq!(plain.velocities, strong.velocities);
    assert_eq!(strong.fracture().expect("it fractures").fragment_count(), 1);
}

fn splits(discontinuity: Discontinuity) {
    let mut fracture = FractureParams::brittle(2e4);
    fracture.discontinuity = discontinuity;
    let mut bar = pulled_bar(Some(fracture), 0.5);
    let before = momentum(&bar);
    let n = bar.len();
    let mut steps = 0;
    while bar.fracture().expect("it fractures").fragment_count() < 2 && steps < 2000 {
        run(&mut bar, 1);
        steps += 1;
    }
    let f = bar.fracture().expect("it fractures");
    assert!(
        f.fragment_count() >= 2,
        "no split after {steps} steps ({} cracks)",
        f.cracks().len()
    );
    // Momentum is exchanged only in pairs, cut or not.
    let drift = (momentum(&bar) - before).norm();
    let scale: Real = bar.masses().iter().sum::<Real>() * 0.5;
    assert!(drift < 1e-10 * scale, "momentum drift {drift:e}");
    // The two largest fragments are the two halves, moving apart.
    let mut sizes = vec![0usize; f.fragment_count() as usize];
    for &k in f.fragments() {
        sizes[k as usize] += 1;
    }
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    assert!(
        sizes[0] + sizes[1] > n * 9 / 10,
        "fragments {sizes:?} of {n}"
    );
    // Left and right of the split no pair still interacts.
    let left = f.fragments()[0];
    let mean = |pick: &dyn Fn(u32) -> bool| {
        let (sum, count) = bar
            .velocities
            .iter()
            .zip(f.fragments())
            .filter(|(_, k)| pick(**k))
            .fold((0.0, 0), |(s, c), (v, _)| (s + v.x, c + 1));
        sum / count as Real
    };
    assert!(mean(&|k| k == left) < 0.0, "the left part moves left");
    assert!(
        bar.undersampling()
            .iter()
            .cloned()
            .fold(Real::INFINITY, Real::min)
            < 10.0
    );
}

#[test]
fn a_bar_pulled_past_its_strength_splits_with_transparency() {
    splits(Discontinuity::Transparency { kappa: 1.0 });
}

#[test]
fn a_bar_pulled_past_its_strength_splits_with_visibility() {
    splits(Discontinuity::Visibility);
}

#[test]
fn fracture_parameters_out_of_range_are_refused_with_what_to_change() {
    let mut p = FractureParams::brittle(-1.0);
    assert!(
        p.validate(0.05, false, false)
            .expect_err("refused")
            .to_string()
            .contains("stress must be positive")
    );
    p = FractureParams::brittle(1e6);
    p.discontinuity = Discontinuity::Transparency { kappa: 0.0 };
    assert!(
        p.validate(0.05, false, false)
            .expect_err("refused")
            .to_string()
            .contains("kappa")
    );
    p = FractureParams::brittle(1e6);
    p.advance = 2.0;
    assert!(
        p.validate(0.05, false, false)
            .expect_err("refused")
            .to_string()
            .contains("advance")
    );
    p.advance = 0.5;
    for cell in [0.2, 1.5, Real::NAN] {
        p.surface_cell = cell;
        let refused = p.validate(0.05, false, false).expect_err("refused");
        assert!(
            refused.to_string().contains("surface_cell"),
            "{cell}: {refused}"
        );
    }
    p.surface_cell = FractureParams::DEFAULT_SURFACE_CELL;
    p.threshold = Threshold::PlasticStrain {
        plastic_strain: 0.1,
    };
    assert_eq!(
        p.validate(0.05, false, false),
        Err(FractureParamsError::NeedsPlasticity)
    );
    assert_eq!(
        p.validate(0.05, true, true),
        Err(FractureParamsError::Rebase)
    );
    assert_eq!(p.validate(0.05, true, false), Ok(()));
}

#[test]
fn a_step_undone_puts_the_cracks_and_the_weights_back_bit_for_bit() {
    let mut fracture = FractureParams::brittle(2e4);
    fracture.discontinuity = Discontinuity::Transparency { kappa: 1.0 };
    let mut bar = pulled_bar(Some(fracture), 0.5);
    // Run until just before the first crack, keep a copy, save.
    while {
        let mut probe = bar.clone();
        run(&mut probe, 1) == 0
    } {
        run(&mut bar, 1);
    }
    let copy = bar.clone();
    let mut saved = crate::solid::SolidState::default();
    bar.save(&mut saved);
    assert!(run(&mut bar, 3) > 0, "a crack starts");
    bar.restore(&saved);
    let mut copy = copy;
    run(&mut bar, 30);
    run(&mut copy, 30);
    assert!(
        bar.positions == copy.positions,
        "positions differ after the undo"
    );
    assert!(
        bar.fracture() == copy.fracture(),
        "cracks differ after the undo"
    );
}

/// A 3D block of 15 x 5 x 5 particles whose halves are pulled apart
/// along x.
fn pulled_block(fracture: FractureParams) -> ElasticSolid {
    let p = SolidParams {
        dim: 3,
        spacing: 0.02,
        support: 0.04,
        ..params(3, Some(fracture))
    };
    let shape = Shape::Box {
        half_extents: Vector::new(0.15, 0.05, 0.05),
    };
    let rest = shape.sample_volume(p.spacing, 3).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(0.5 * x.x.signum(), 0.0, 0.0))
        .collect();
    let n = rest.len();
    ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default()).expect("solid")
}

#[test]
fn a_3d_block_pulled_apart_cracks_with_growing_discs_and_splits() {
    let mut block = pulled_block(FractureParams::brittle(2e4));
    let before = momentum(&block);
    let mut steps = 0;
    while block.fracture().expect("it fractures").fragment_count() < 2 && steps < 400 {
        run(&mut block, 1);
        steps += 1;
    }
    let f = block.fracture().expect("it fractures");
    assert!(f.fragment_count() >= 2, "no split after {steps} steps");
    // The discs grew: their rims refined past the six nodes they start
    // with; the first crack opened in the middle, where the halves part,
    // and stayed flat across the pull.
    assert!(f.cracks().iter().any(|c| c.front().len() > 6));
    for node in f.cracks()[0].front() {
        assert!(node.at.x.abs() < 0.03, "a front at x = {}", node.at.x);
    }
    let drift = (momentum(&block) - before).norm();
    assert!(drift < 1e-10, "momentum drift {drift:e}");
    let (mesh, normals) = block.crack_surface().expect("cracks have faces");
    assert_eq!(normals.len(), mesh.vertices.len());
    assert!(mesh.triangles.len() > 2 * f.cracks().len());
}

#[test]
fn a_ductile_bar_tears_only_after_it_has_flowed() {
    let mut fracture = FractureParams::brittle(1.0);
    fracture.threshold = Threshold::PlasticStrain {
        plastic_strain: 0.02,
    };
    let mut p = params(2, Some(fracture));
    p.plasticity = Some(crate::solid::Plasticity {
        yield_strain: 0.002,
        creep: 0.5,
        max: 1.0,
        rebase: None,
    });
    let shape = Shape::Box {
        half_extents: Vector::new(0.5, 0.15, 0.0),
    };
    let rest = shape.sample_volume(p.spacing, 2).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(0.5 * x.x.signum(), 0.0, 0.0))
        .collect();
    let n = rest.len();
    let mut bar =
        ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default()).expect("bar");
    let mut first_crack = None;
    for step in 0..2000 {
        let flowed = bar
            .plastic
            .as_ref()
            .map_or(0.0, |e| e.iter().map(|m| m.norm()).fold(0.0, Real::max));
        if run(&mut bar, 1) > 0 && first_crack.is_none() {
            first_crack = Some((step, flowed));
        }
        if bar.fracture().expect("it fractures").fragment_count() >= 2 {
            break;
        }
    }
    let (step, flowed) = first_crack.expect("the bar tears");
    assert!(step > 0, "it tore before it flowed");
    assert!(
        flowed >= 0.02 * 0.5,
        "the first crack came at a plastic strain of {flowed}"
    );
    assert!(bar.fracture().expect("it fractures").fragment_count() >= 2);
}

#[test]
fn a_bar_stretched_uniformly_cracks_when_its_stress_reaches_the_strength() {
    // A 2D bar with nu = 0 given the velocity field v = rate x: its middle
    // stretches uniformly until the free ends' unloading wave arrives, so
    // its Cauchy stress follows (1 + e) E (e + e^2 / 2) with e = rate t
    // (St Venant-Kirchhoff in 1D), and the first crack must start in the
    // first step whose end puts it past the strength.
    let young = 1e6;
    let strength = 2e4;
    let rate = 5.0;
    let mut p = params(2, Some(FractureParams::brittle(strength)));
    p.material = Material::from_young_poisson(young, 0.0, 0.0);
    p.hourglass = 0.0;
    let shape = Shape::Box {
        half_extents: Vector::new(1.0, 0.1, 0.0),
    };
    let rest = shape.sample_volume(p.spacing, 2).expect("samples");
    let velocities = rest
        .iter()
        .map(|x| Vector::new(rate * x.x, 0.0, 0.0))
        .collect();
    let n = rest.len();
    let mut bar =
        ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default()).expect("bar");
    let dt = 2e-4;
    let stress = |t: Real| {
        let e = rate * t;
        (1.0 + e) * young * (e + 0.5 * e * e)
    };
    let expected: u32 = (1..)
        .find(|&k| stress(Real::from(k) * dt) >= strength)
        .expect("reached");
    // The unloading wave from the ends (1 m away, c = sqrt(E / rho))
    // arrives well after.
    assert!(Real::from(expected) * dt < 1.0 / (young / 1000.0_f64).sqrt());
    let mut started = None;
    for k in 1..=2 * expected {
        bar.step(dt, &Vector::zeros(), 100);
        if bar.fracture_step().expect("bounded").started > 0 {
            started = Some(k);
            break;
        }
    }
    let started = started.expect("a crack starts");
    assert!(
        started.abs_diff(expected) <= 1,
        "the first crack came in step {started}; the strength is reached in step {expected}"
    );
    let first = &bar.fracture().expect("it fractures").cracks()[0];
    let x = first.front().iter().map(|f| f.at.x).sum::<Real>() / first.front().len() as Real;
    assert!(
        x.abs() < 0.8,
        "the first crack is at x = {x}, in the uniform middle"
    );
}

#[test]
fn a_refit_reports_exactly_what_it_changed_the_stored_energy_by() {
    let mut bar = pulled_bar(Some(FractureParams::brittle(2e4)), 0.5);
    let mut checked = 0;
    for _ in 0..200 {
        bar.step(2e-4, &Vector::zeros(), 100);
        let before = bar.potential_energy();
        let update = bar.fracture_step().expect("bounded");
        let after = bar.potential_energy();
        if update.refitted > 0 {
            let error = (after - before - update.energy_change).abs();
            assert!(
                error <= 1e-9 * before.abs().max(1e-9),
                "{error:e} of {before:e}"
            );
            checked += 1;
        }
    }
    assert!(checked > 5, "only {checked} updates refitted");
}

#[test]
fn after_a_split_each_side_still_reproduces_linear_fields_and_momenta_hold() {
    let mut bar = pulled_bar(Some(FractureParams::brittle(2e4)), 0.5);
    // A spin on top of the pull, for the angular momentum.
    let spin = Vector::new(0.0, 0.0, 0.3);
    let rest = bar.rest_positions().to_vec();
    for (v, x) in bar.velocities.iter_mut().zip(&rest) {
        *v += spin.cross(x);
    }
    let angular = |b: &ElasticSolid| -> Vector {
        b.positions
            .iter()
            .zip(&b.velocities)
            .zip(b.masses())
            .map(|((x, v), m)| x.cross(&(v * *m)))
            .sum()
    };
    let (p0, l0) = (momentum(&bar), angular(&bar));
    let mut steps = 0;
    while bar.fracture().expect("it fractures").fragment_count() < 2 && steps < 2000 {
        run(&mut bar, 1);
        steps += 1;
    }
    assert!(bar.fracture().expect("it fractures").fragment_count() >= 2);
    assert!((momentum(&bar) - p0).norm() < 1e-10, "linear momentum");
    let drift = (angular(&bar) - l0).norm();
    assert!(drift < 1e-10, "angular momentum drift {drift:e}");
    // Every particle that kept a linear fit still differentiates a linear
    // field exactly, whatever pairs the cracks removed from it.
    let field = |x: &Vector| 0.3 + 1.7 * x.x - 0.8 * x.y;
    let values: Vec<Real> = rest.iter().map(field).collect();
    let g = &bar.topology.gradients;
    let mut linear = 0;
    for i in 0..bar.len() {
        if g.orders()[i] != Order::Linear {
            continue;
        }
        linear += 1;
        let grad = g.scalar_gradient(i, &values);
        assert!(
            (grad - Vector::new(1.7, -0.8, 0.0)).norm() < 1e-10,
            "particle {i}: {grad:?}"
        );
    }
    assert!(
        linear > bar.len() * 9 / 10,
        "{linear} of {} still linear",
        bar.len()
    );
}

/// A 1 m plate of next to no strength (1 Pa, up to 4096 cracks) at
/// `scale` times the test spacing, pulled apart from its centre in every
/// direction.
fn shattering_plate(discontinuity: Discontinuity, scale: Real) -> ElasticSolid {
    let mut fracture = FractureParams::brittle(1.0);
    fracture.max_cracks = 4096;
    fracture.discontinuity = discontinuity;
    let mut p = params(2, Some(fracture));
    p.spacing *= scale;
    p.support *= scale;
    let shape = Shape::Box {
        half_extents: Vector::new(0.5, 0.5, 0.0),
    };
    let rest = shape.sample_volume(p.spacing, 2).expect("samples");
    let velocities = rest.iter().map(|x| x * 2.0).collect();
    let n = rest.len();
    ElasticSolid::new(p, rest, velocities, vec![false; n], Obstacles::default()).expect("plate")
}

#[test]
fn a_plate_with_next_to_no_strength_shatters_into_many_fragments_and_stays_finite() {
    let mut plate = shattering_plate(Discontinuity::default(), 1.0);
    let p0 = momentum(&plate);
    run(&mut plate, 40);
    let f = plate.fracture().expect("it fractures");
    assert!(f.fragment_count() > 20, "{} fragments", f.fragment_count());
    assert!(f.cracks().len() > 20, "{} cracks", f.cracks().len());
    assert!(
        plate
            .positions
            .iter()
            .all(|x| x.iter().all(|c| c.is_finite()))
    );
    assert!(
        plate.velocities.iter().all(|v| v.norm() < 10.0),
        "a particle was flung"
    );
    assert!((momentum(&plate) - p0).norm() < 1e-9);
    let (mesh, _) = plate.crack_surface().expect("faces");
    assert!(
        mesh.vertices
            .iter()
            .all(|x| x.iter().all(|c| c.is_finite()))
    );
}

#[test]
fn a_toughness_samples_at_its_critical_distance_and_refuses_one_the_particles_miss() {
    let toughness = Threshold::Toughness {
        stress: 1e6,
        toughness: 2e5,
    };
    // r_c = K_Ic^2 / (2 pi sigma_0^2): the point method's half of
    // Taylor's L = (K_Ic / sigma_0)^2 / pi.
    let l = (2e5_f64 / 1e6).powi(2) / std::f64::consts::PI;
    let rc = toughness.critical_distance().expect("a toughness has one");
    assert!((rc - 0.5 * l).abs() < 1e-15, "{rc}");
    assert_eq!(Threshold::Stress { stress: 1.0 }.critical_distance(), None);
    let mut p = FractureParams::brittle(1e6);
    p.threshold = toughness;
    assert_eq!(p.validate(0.5 * rc, false, false), Ok(()));
    let refused = p
        .validate(2.0 * rc, false, false)
        .expect_err("under a spacing");
    assert!(matches!(refused, FractureParamsError::Unresolved { .. }));
    assert!(
        refused.to_string().contains("refine the spacing"),
        "{refused}"
    );
    p.threshold = Threshold::Toughness {
        stress: 1e6,
        toughness: -1.0,
    };
    assert!(matches!(
        p.validate(0.01, false, false),
        Err(FractureParamsError::OutOfRange {
            what: "toughness",
            ..
        })
    ));
}

#[test]
fn a_notch_across_the_whole_bar_splits_it_at_the_build_and_one_inside_cuts_its_pairs() {
    let notch = |radius| Notch {
        center: Vector::zeros(),
        normal: Vector::x(),
        radius,
    };
    let mut p = FractureParams::brittle(1e9);
    p.discontinuity = Discontinuity::Visibility;
    // Across the 0.3 m bar's middle and past both its sides.
    let mut through = pulled_bar(Some(p), 0.0);
    through.notch(&[notch(0.5)]).expect("a valid notch");
    let fracture = through.fracture().expect("fractures");
    assert_eq!(fracture.fragment_count(), 2);
    let rest = through.rest_positions();
    let sides: Vec<_> = fracture.fragments().iter().zip(rest).collect();
    assert!(
        sides.iter().all(|(k, x)| (**k == 0) == (x.x < 0.0)),
        "the fragments are not the bar's halves"
    );

    // Half as long: the pairs across it are cut, the body stays one
    // piece, and the crack's tips are its front.
    let mut inside = pulled_bar(Some(p), 0.0);
    inside.notch(&[notch(0.05)]).expect("a valid notch");
    let fracture = inside.fracture().expect("fractures");
    assert_eq!(fracture.fragment_count(), 1);
    let crack = &fracture.cracks()[0];
    assert_eq!(crack.front().len(), 2);
    assert!(
        crack
            .front()
            .iter()
            .all(|n| n.active && (n.at.y.abs() - 0.05).abs() < 1e-12)
    );
    // Eq. 71's count falls beside the notch only.
    let plain = pulled_bar(Some(p), 0.0).undersampling();
    let cut = inside.undersampling();
    for (i, x) in inside.rest_positions().iter().enumerate() {
        let beside = x.x.abs() < 0.1 && x.y.abs() < 0.05 + 0.1;
        if beside && x.x.abs() < 0.05 && x.y.abs() < 0.05 {
            assert!(cut[i] < plain[i], "particle {i} at {x:?} lost no neighbour");
        } else if !beside {
            assert_eq!(
                cut[i], plain[i],
                "particle {i} at {x:?} far from the notch changed"
            );
        }
    }

    // Refused, leaving the body as it was: a zero normal, z in 2D, too
    // many cracks, a solid that does not fracture.
    let before = inside.fracture().cloned();
    for bad in [
        Notch {
            normal: Vector::zeros(),
            ..notch(0.1)
        },
        Notch {
            center: Vector::new(0.0, 0.0, 0.1),
            ..notch(0.1)
        },
        notch(Real::NAN),
    ] {
        assert!(matches!(
            inside.notch(&[bad]),
            Err(FractureParamsError::Notch(_))
        ));
        assert_eq!(inside.fracture().cloned(), before);
    }
    p.max_cracks = 1;
    let mut full = pulled_bar(Some(p), 0.0);
    full.notch(&[notch(0.05)]).expect("one fits");
    assert!(full.notch(&[notch(0.05)]).is_err());
    let mut elastic = pulled_bar(None, 0.0);
    assert!(elastic.notch(&[notch(0.05)]).is_err());
}

#[test]
fn a_3d_notch_is_a_disc_whose_rim_is_as_fine_as_the_particles() {
    let spacing = 0.05;
    let notch = Notch {
        center: Vector::zeros(),
        normal: Vector::z(),
        radius: 0.2,
    };
    let crack = Crack::notch(3, &notch, spacing, 0.1);
    let rim = crack.front();
    assert_eq!(rim.len() + 1, Crack::notch_vertices(3, &notch, spacing));
    for (k, node) in rim.iter().enumerate() {
        assert!((node.at.norm() - 0.2).abs() < 1e-12);
        assert!((node.at - rim[(k + 1) % rim.len()].at).norm() <= spacing);
    }
    // A segment through its middle crosses it; one beside it does not.
    let up = Vector::new(0.0, 0.0, 0.1);
    assert!(
        crack
            .crossing(&(Vector::x() * 0.1 - up), &(Vector::x() * 0.1 + up))
            .is_some()
    );
    assert!(
        crack
            .crossing(&(Vector::x() * 0.3 - up), &(Vector::x() * 0.3 + up))
            .is_none()
    );
}

#[test]
fn the_closed_form_largest_principal_value_agrees_with_the_decomposition() {
    use nalgebra::Matrix3;
    // A fixed pseudo-random sequence: symmetric matrices of mixed signs
    // and scales, and the degenerate ones (diagonal, repeated values).
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
    };
    let mut cases = vec![
        Matrix3::zeros(),
        Matrix3::identity() * 3.0,
        Matrix3::from_diagonal(&Vector::new(-1.0, 5.0, 2.0)),
        Matrix3::new(2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 3.0),
    ];
    for _ in 0..500 {
        let scale = 10.0_f64.powf(6.0 * next());
        let a = Matrix3::from_fn(|_, _| next() * scale);
        cases.push(a + a.transpose());
    }
    for m in cases {
        for dim in [2, 3] {
            let exact = principal(dim, &m).0;
            let closed = largest_principal(dim, &m);
            // Where two values coincide the cubic's roots are
            // ill-conditioned and the trigonometric form loses half the
            // digits; a threshold test needs far fewer.
            let scale = m.norm().max(1e-300);
            assert!(
                (closed - exact).abs() <= 1e-7 * scale,
                "dim {dim}: {closed} against {exact} for {m}"
            );
        }
    }
}

#[test]
fn the_scans_stress_bound_is_never_below_the_largest_principal_stress() {
    let material = Material::from_young_poisson(1e6, 0.3, 0.0);
    let mut seed: u64 = 0x2545_f491_4f6c_dd1d;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
    };
    for k in 0..2000 {
        // Small strains, large ones, and inverted elements.
        let size = [1e-4, 1e-2, 0.5, 2.0][k % 4];
        let f = nalgebra::Matrix3::identity() + nalgebra::Matrix3::from_fn(|_, _| next() * size);
        let state = material.state(f, None);
        for dim in [2, 3] {
            let sigma = largest_principal(dim, &cauchy(&state));
            assert!(
                stress_bound(&state) >= sigma * (1.0 - 1e-12),
                "bound {} below {sigma} for F = {f}",
                stress_bound(&state)
            );
        }
    }
    // For a small uniaxial stretch it is within a fifth of the stress (the
    // lateral stresses that Poisson's ratio brings count in |S|_F): the
    // scan decomposes only particles near their threshold.
    let state = material.state(
        nalgebra::Matrix3::from_diagonal(&Vector::new(1.001, 1.0, 1.0)),
        None,
    );
    let sigma = largest_principal(3, &cauchy(&state));
    assert!(
        stress_bound(&state) < 1.2 * sigma,
        "{} against {sigma}",
        stress_bound(&state)
    );
}

#[test]
fn a_front_past_its_branching_stress_splits_into_two_arms_thirty_degrees_apart() {
    let run_with = |branching: Option<Real>| {
        let mut fracture = FractureParams::brittle(2e4);
        fracture.branching = branching;
        branching_run(pulled_bar(Some(fracture), 0.5), 300)
    };
    let (_, plain, _) = run_with(None);
    assert_eq!(plain, 0);
    let (_, never, _) = run_with(Some(1e9));
    assert_eq!(never, 0, "a front branched below its branching stress");

    let (bar, branched, arms) = run_with(Some(1.0));
    assert!(branched > 0, "no front branched");
    let fracture = bar.fracture().expect("it fractures");
    for arm in &arms {
        // One end stopped at the junction, on another crack's path ...
        let junction = arm.front().iter().find(|n| !n.active).expect("a junction");
        let on_parent = fracture
            .cracks()
            .iter()
            .filter(|c| !std::ptr::eq(*c, arm) && c.vertices() != arm.vertices())
            .any(|c| c.distance_to_vertices(&junction.at) < 1e-9);
        assert!(
            on_parent,
            "a branch whose junction {:?} is on no crack",
            junction.at
        );
        // ... the other running, away from the junction.
        let tip = arm
            .front()
            .iter()
            .find(|n| n.active)
            .expect("a running end");
        assert!((tip.at - junction.at).dot(&tip.heading) >= 0.0);
    }
    assert!(fracture.cracks().len() <= FractureParams::DEFAULT_MAX_CRACKS as usize);
}

/// The extreme of many fragments: a 25,600-particle plate with next to no
/// strength pulled apart from its centre starts thousands of cracks at
/// once and is in thousands of pieces within a dozen steps, finite, its
/// momentum kept (and fast enough to test: the pairs ask only the cracks
/// near them, `CrackIndex`).
#[test]
fn a_plate_shatters_into_thousands_of_fragments_and_stays_finite() {
    let mut plate = shattering_plate(Discontinuity::Visibility, 0.125);
    let p0 = momentum(&plate);
    run(&mut plate, 12);
    let f = plate.fracture().expect("it fractures");
    assert!(f.cracks().len() > 2000, "{} cracks", f.cracks().len());
    assert!(
        f.fragment_count() > 2000,
        "{} fragments",
        f.fragment_count()
    );
    assert!(
        plate
            .positions
            .iter()
            .chain(&plate.velocities)
            .all(|x| x.iter().all(|c| c.is_finite()))
    );
    assert!(
        plate.velocities.iter().all(|v| v.norm() < 10.0),
        "a particle was flung"
    );
    assert!((momentum(&plate) - p0).norm() < 1e-9);
}

/// Each closed component of `mesh` (triangles joined by shared edges):
/// its vertex indices and enclosed volume; fails unless every edge is
/// used once in each direction (closed and consistently wound).
fn closed_components(mesh: &crate::geometry::TriMesh) -> Vec<(Vec<usize>, Real)> {
    use std::collections::HashMap;
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let edge = (tri[k], tri[(k + 1) % 3]);
            assert!(
                directed.insert(edge, t).is_none(),
                "edge {edge:?} used twice one way"
            );
        }
    }
    let mut part: Vec<usize> = (0..mesh.triangles.len()).collect();
    fn root(part: &mut [usize], mut t: usize) -> usize {
        while part[t] != t {
            part[t] = part[part[t]];
            t = part[t];
        }
        t
    }
    for (&(a, b), &t) in &directed {
        let other = *directed
            .get(&(b, a))
            .unwrap_or_else(|| panic!("edge ({a}, {b}) has no twin: the surface is open"));
        let (r, s) = (root(&mut part, t), root(&mut part, other));
        part[r] = s;
    }
    let mut components: HashMap<usize, (Vec<usize>, Real)> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let r = root(&mut part, t);
        let [a, b, c] = tri.map(|v| mesh.vertices[v as usize]);
        let entry = components.entry(r).or_default();
        entry.0.extend(tri.iter().map(|&v| v as usize));
        entry.1 += a.dot(&b.cross(&c)) / 6.0;
    }
    components.into_values().collect()
}

#[test]
fn a_block_in_two_pieces_shows_two_closed_surfaces_that_part_with_their_pieces() {
    // Through the block's whole section, between its two middle planes of
    // particles (x = -0.01 and 0.01) and off the grid's nodes.
    let cut = 0.004;
    let mut p = FractureParams::brittle(1e9);
    p.discontinuity = Discontinuity::Visibility;
    let mut block = pulled_block(p);
    let half = Vector::new(0.15, 0.05, 0.05);
    let outline = crate::geometry::MeshSdf::new(&crate::geometry::TriMesh::cuboid(-half, half))
        .expect("a closed box");
    assert!(
        block.fragment_surface(&outline).is_none(),
        "one piece keeps its embedded surface"
    );
    block
        .notch(&[Notch {
            center: Vector::new(cut, 0.0, 0.0),
            normal: Vector::x(),
            radius: 0.2,
        }])
        .expect("a valid notch");
    assert_eq!(block.fracture().expect("fractures").fragment_count(), 2);

    let (mesh, normals) = block.fragment_surface(&outline).expect("two pieces");
    assert_eq!(normals.len(), mesh.vertices.len());
    assert!(normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-9));
    let mut parts = closed_components(&mesh);
    assert_eq!(parts.len(), 2, "one closed surface per piece");
    parts.sort_by(|a, b| mesh.vertices[a.0[0]].x.total_cmp(&mesh.vertices[b.0[0]].x));
    // Each on its own side of the cut, its crack face within a hundredth
    // of a cell of the cut, and enclosing its piece's volume.
    let side = |(vertices, _): &(Vec<usize>, Real)| {
        let xs: Vec<Real> = vertices.iter().map(|&v| mesh.vertices[v].x).collect();
        (
            xs.iter().copied().fold(Real::INFINITY, Real::min),
            xs.iter().copied().fold(Real::NEG_INFINITY, Real::max),
        )
    };
    let (left, right) = (side(&parts[0]), side(&parts[1]));
    assert!(
        (left.1 - cut).abs() < 1e-4,
        "left piece ends at x = {}",
        left.1
    );
    assert!(
        (right.0 - cut).abs() < 1e-4,
        "right piece starts at x = {}",
        right.0
    );
    let section = 4.0 * half.y * half.z;
    for ((_, volume), expected) in parts
        .iter()
        .zip([(cut + half.x) * section, (half.x - cut) * section])
    {
        assert!(
            (volume / expected - 1.0).abs() < 0.03,
            "volume {volume:e} against {expected:e}"
        );
    }

    // Pulled apart, each surface moves with its own piece: the gap between
    // them opens as the pieces' inner faces part.
    run(&mut block, 100);
    let (moved, _) = block.fragment_surface(&outline).expect("two pieces");
    let mut parts = closed_components(&moved);
    assert_eq!(parts.len(), 2);
    parts.sort_by(|a, b| {
        moved.vertices[a.0[0]]
            .x
            .total_cmp(&moved.vertices[b.0[0]].x)
    });
    let max_left = parts[0]
        .0
        .iter()
        .map(|&v| moved.vertices[v].x)
        .fold(Real::NEG_INFINITY, Real::max);
    let min_right = parts[1]
        .0
        .iter()
        .map(|&v| moved.vertices[v].x)
        .fold(Real::INFINITY, Real::min);
    let rest = block.rest_positions();
    let inner = |sign: Real| {
        let (sum, count) = rest
            .iter()
            .zip(&block.positions)
            .filter(|(x, _)| sign * (x.x - cut) > 0.0 && (x.x - cut).abs() < 0.015)
            .fold((0.0, 0.0), |(s, c), (x, y)| (s + y.x - x.x, c + 1.0));
        sum / count
    };
    let opened = inner(1.0) - inner(-1.0);
    assert!(opened > 0.01, "the pieces parted by {opened}");
    let gap = min_right - max_left;
    assert!(
        (gap - opened).abs() < 0.25 * opened,
        "surfaces {gap} apart, pieces {opened}"
    );
}

#[test]
fn a_block_in_four_pieces_shows_four_closed_surfaces_that_fill_it() {
    let (total, expected) = four_pieces(FractureParams::DEFAULT_SURFACE_CELL);
    // Marching cubes bevels every edge of every piece (its cell is 1 cm
    // here, on a block 10 cm across): the four pieces hold 97 % of it.
    assert!(
        (total / expected - 1.0).abs() < 0.05,
        "the pieces hold {total:e} of {expected:e}"
    );
}

#[test]
fn a_finer_surface_cell_bevels_the_pieces_less() {
    let (coarse, expected) = four_pieces(0.5);
    let (fine, _) = four_pieces(0.25);
    let (missing_coarse, missing_fine) = (1.0 - coarse / expected, 1.0 - fine / expected);
    // The bevels' volume follows the cell: at half the cell, under half
    // the volume missing (3.0 % at half a spacing, 0.8 % at a quarter).
    assert!(
        missing_fine > 0.0 && missing_fine < 0.5 * missing_coarse,
        "missing {missing_fine} at a quarter spacing, {missing_coarse} at half"
    );
}

/// The volume the four closed surfaces of the pulled block cut in four
/// enclose at `surface_cell`, and the block's.
fn four_pieces(surface_cell: Real) -> (Real, Real) {
    let mut p = FractureParams::brittle(1e9);
    p.discontinuity = Discontinuity::Visibility;
    p.surface_cell = surface_cell;
    let mut block = pulled_block(p);
    let cuts = [-0.076, 0.004, 0.084];
    let notches: Vec<Notch> = cuts
        .iter()
        .map(|&x| Notch {
            center: Vector::new(x, 0.0, 0.0),
            normal: Vector::x(),
            radius: 0.2,
        })
        .collect();
    block.notch(&notches).expect("valid notches");
    assert_eq!(block.fracture().expect("fractures").fragment_count(), 4);
    let half = Vector::new(0.15, 0.05, 0.05);
    let outline = crate::geometry::MeshSdf::new(&crate::geometry::TriMesh::cuboid(-half, half))
        .expect("a closed box");
    let (mesh, _) = block.fragment_surface(&outline).expect("four pieces");
    let parts = closed_components(&mesh);
    assert_eq!(parts.len(), 4, "one closed surface per piece");
    let total: Real = parts.iter().map(|(_, v)| v).sum();
    (total, 8.0 * half.x * half.y * half.z)
}
