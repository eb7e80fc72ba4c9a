//! Validation of the shape and motion optimiser (tutorial Section 8)
//! against the tutorial's own Figure 13 and against properties the
//! energies promise: handles met, rigid motions kept rigid, keyframes
//! met, smoother than linear interpolation, velocities matched, obstacles
//! avoided between frames thanks to adaptive temporal sampling.
//!
//!     cargo test -p meshless-tests --test validation_design -- --nocapture

use meshless_engine::design::{
    Constraint, ConstraintKind, ConstraintSet, Context, DesignError, DesignParams, Edit,
    MotionParams, Quadrature, Velocity, solve_motion, solve_shape,
};
use meshless_engine::math::{Real, Vector};
use meshless_validation::design::{Passage, Stretch, region_handle, stretch_params};
use nalgebra::Rotation3;
use std::ops::ControlFlow;

fn set_of(constraints: Vec<Constraint>) -> ConstraintSet {
    let mut set = ConstraintSet::new();
    let edits: Vec<Edit> = constraints.into_iter().map(Edit::Add).collect();
    set.apply(
        &edits,
        &Context {
            dim: 3,
            solids: vec![],
        },
    )
    .expect("valid constraints");
    set
}

/// Keyframes on the whole cube at `(time, x)`.
fn keyframes_along_x(keys: &[(Real, Real)]) -> Vec<Constraint> {
    keys.iter()
        .enumerate()
        .map(|(k, &(t, x))| {
            region_handle(
                &format!("key{k}"),
                [-1.0; 3],
                [1.0; 3],
                [x, 0.0, 0.0],
                [0.0; 3],
                Some(t),
            )
        })
        .collect()
}

/// Figure 13: rigidity alone lets the stretched box gain about half its
/// volume (the tutorial reports +53 %); the volume energy holds it within
/// 3 %. Both measured on the embedded surface, the shape a user sees.
#[test]
fn figure_13_volume_with_and_without_the_volume_energy() {
    let stretch = Stretch::default();
    let rigid = stretch.solve(&stretch_params(false)).expect("solves");
    let kept = stretch.solve(&stretch_params(true)).expect("solves");
    // The tutorial's quadrature: rigidity and volume at the particles.
    let at_particles = stretch
        .solve(&DesignParams {
            quadrature: Quadrature::Particles,
            ..stretch_params(true)
        })
        .expect("solves");
    println!(
        "Figure 13 ({} particles): rigidity only {:+.1} % (surface) {:+.1} % (particles); \
         with volume {:+.1} % (surface) {:+.2} % (particles); handles within {:.3} / {:.3} \
         spacings; {:?} / {:?}",
        rigid.particles,
        100.0 * rigid.volume_change,
        100.0 * rigid.discrete_volume_change,
        100.0 * kept.volume_change,
        100.0 * kept.discrete_volume_change,
        rigid.handle_error,
        kept.handle_error,
        rigid.elapsed,
        kept.elapsed,
    );
    println!(
        "  with volume measured at the particles only: {:+.1} % (surface) {:+.2} % (particles)",
        100.0 * at_particles.volume_change,
        100.0 * at_particles.discrete_volume_change
    );
    assert!(
        at_particles.volume_change > kept.volume_change,
        "measuring at the cells should hold the surface's volume closer than at the particles"
    );
    assert!(
        (0.35..0.75).contains(&rigid.volume_change),
        "rigidity alone should let the volume grow by about half (tutorial: +53 %), got {:+.1} %",
        100.0 * rigid.volume_change
    );
    assert!(
        kept.volume_change.abs() < 0.03,
        "the volume energy should hold the volume within 3 %, got {:+.1} %",
        100.0 * kept.volume_change
    );
    for (what, r) in [("rigidity only", &rigid), ("with volume", &kept)] {
        assert!(r.solution.info.converged, "{what}: {:?}", r.solution.info);
        assert!(
            r.handle_error < 0.1,
            "{what}: handles should be met within 0.1 spacing, worst {:.3}",
            r.handle_error
        );
    }
}

/// Handles that all move by one rigid motion leave nothing to resist:
/// the optimum is that rigid motion, with zero rigidity energy.
#[test]
fn a_rigid_motion_of_every_handle_gives_a_rigid_field() {
    let stretch = Stretch::default();
    let params = stretch_params(true);
    let body = stretch.body(&params).expect("body");
    let rotation = [0.0, 0.6, 0.3];
    let shift = [0.4, -0.2, 0.7];
    let set = set_of(vec![
        region_handle(
            "bottom",
            [-1.0, -1.0, -2.0],
            [1.0, 1.0, -0.8],
            shift,
            rotation,
            None,
        ),
        region_handle(
            "top",
            [-1.0, -1.0, 0.8],
            [1.0, 1.0, 2.0],
            shift,
            rotation,
            None,
        ),
    ]);
    // A first solve starts from the rest shape carried by the rigid
    // motion that best fits the handles, which here is the answer; from
    // the rest shape itself the solver has to find it.
    let rest = vec![Vector::zeros(); body.len()];
    let r = Rotation3::from_scaled_axis(Vector::from(rotation));
    for (start, warm) in [("fitted", None), ("rest", Some(rest.as_slice()))] {
        let s = solve_shape(&body, &set, &params, warm, &mut |_| {
            ControlFlow::Continue(())
        })
        .expect("solves");
        let worst = body
            .rest()
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let at = x + body.field().displacement(i, &s.displacements);
                (at - (r * x + Vector::from(shift))).norm() / body.spacing()
            })
            .fold(0.0, Real::max);
        println!(
            "rigid handles from the {start} start: {:?}, worst deviation {worst:.2e} spacings",
            s.info
        );
        assert!(
            s.info.energies.rigidity < 1e-6,
            "{start}: rigidity energy {:e} should vanish",
            s.info.energies.rigidity
        );
        assert!(
            worst < 1e-3,
            "{start}: field deviates {worst:e} spacings from the rigid motion"
        );
        if warm.is_none() {
            assert_eq!(
                s.info.iterations, 0,
                "the fitted start is the rigid motion itself"
            );
        }
    }
}

/// Keyframes met, and the ball cleared at every one of 201 times only
/// with adaptive temporal sampling: without it the frames are only the
/// keyframes, where the cube is nowhere near the ball.
#[test]
fn adaptive_sampling_clears_the_obstacle_between_keyframes() {
    let passage = Passage::default();
    let params = DesignParams::default();
    let fixed = passage
        .solve(
            &params,
            &MotionParams {
                adaptive: false,
                ..MotionParams::default()
            },
        )
        .expect("solves");
    let adaptive = passage
        .solve(&params, &MotionParams::default())
        .expect("solves");
    println!(
        "passage ({} particles): without adaptive sampling {} frames, penetration {:.3} \
         spacings, {:?}; with it {} frames ({} inserted), penetration {:.3} spacings, keyframes \
         within {:.3} spacings, {:?}",
        fixed.particles,
        fixed.solution.times().len(),
        fixed.penetration,
        fixed.elapsed,
        adaptive.solution.times().len(),
        adaptive.solution.info.inserted,
        adaptive.penetration,
        adaptive.keyframe_error,
        adaptive.elapsed,
    );
    assert!(
        fixed.penetration > 0.5,
        "without adaptive sampling the cube should pass through the ball, penetration {:.3}",
        fixed.penetration
    );
    assert!(
        adaptive.penetration < 0.1,
        "with adaptive sampling no particle sphere should penetrate more than 0.1 spacing (the \
         penalty's give), got {:.3}",
        adaptive.penetration
    );
    assert!(adaptive.solution.info.inserted > 0);
    assert!(
        adaptive.keyframe_error < 0.1,
        "keyframes should be met within 0.1 spacing, worst {:.3}",
        adaptive.keyframe_error
    );
}

/// Keyframes at x = 0, 1, 3 m (t = 0, 1, 2 s): linear interpolation
/// turns sharply at t = 1, the optimised motion accelerates smoothly.
/// Acceleration is measured on both the same way, by second differences
/// of the particles' positions at 201 times.
#[test]
fn the_motion_is_smoother_than_linear_interpolation() {
    let passage = Passage {
        obstacle: false,
        ..Passage::default()
    };
    let params = DesignParams::default();
    let body = passage.body(&params).expect("body");
    let keys = [(0.0, 0.0), (1.0, 1.0), (2.0, 3.0)];
    let set = set_of(keyframes_along_x(&keys));
    let motion = solve_motion(&body, &set, &params, &MotionParams::default(), &mut |_| {
        ControlFlow::Continue(())
    })
    .expect("solves");
    let dt = 2.0 / 200.0;
    let optimised: Vec<Vec<Vector>> = (0..=200)
        .map(|k| {
            let u = motion.displacements_at(k as Real * dt).expect("in span");
            (0..body.len())
                .map(|i| body.rest()[i] + body.field().displacement(i, &u))
                .collect()
        })
        .collect();
    let linear: Vec<Vec<Vector>> = (0..=200)
        .map(|k| {
            let t = k as Real * dt;
            let x = if t <= 1.0 { t } else { 1.0 + 2.0 * (t - 1.0) };
            body.rest()
                .iter()
                .map(|p| p + Vector::new(x, 0.0, 0.0))
                .collect()
        })
        .collect();
    let energy = |path: &[Vec<Vector>]| -> Real {
        (1..200)
            .map(|k| {
                (0..body.len())
                    .map(|i| {
                        ((path[k + 1][i] - 2.0 * path[k][i] + path[k - 1][i]) / (dt * dt))
                            .norm_squared()
                            * dt
                    })
                    .sum::<Real>()
            })
            .sum::<Real>()
            / body.len() as Real
    };
    let (smooth, kinked) = (energy(&optimised), energy(&linear));
    let key_error = keys
        .iter()
        .map(|&(t, x)| {
            let k = (t / dt).round() as usize;
            (0..body.len())
                .map(|i| (optimised[k][i] - body.rest()[i] - Vector::new(x, 0.0, 0.0)).norm())
                .fold(0.0, Real::max)
        })
        .fold(0.0, Real::max)
        / body.spacing();
    println!(
        "acceleration energy per particle: optimised {smooth:.3}, linear interpolation \
         {kinked:.3} (m^2/s^3); keyframes within {key_error:.3} spacings; {:?}",
        motion.info
    );
    assert!(
        smooth < 0.5 * kinked,
        "the optimised motion ({smooth:.3}) should accelerate far less than linear \
         interpolation ({kinked:.3})"
    );
    assert!(
        key_error < 0.1,
        "keyframes missed by {key_error:.3} spacings"
    );
}

/// A velocity prescribed at the first keyframe (Eq. 82) is matched by
/// the field's time derivative there.
#[test]
fn a_keyframe_velocity_is_matched() {
    let passage = Passage {
        obstacle: false,
        ..Passage::default()
    };
    let params = DesignParams::default();
    let body = passage.body(&params).expect("body");
    let target = Vector::new(0.0, 1.5, 0.0);
    let mut constraints = keyframes_along_x(&[(0.0, 0.0), (1.0, 2.0), (2.0, 4.0)]);
    constraints.push(Constraint {
        name: "launch".into(),
        kind: ConstraintKind::Velocity(Velocity {
            time: 0.0,
            velocity: target.into(),
            points: None,
        }),
    });
    let motion = solve_motion(
        &body,
        &set_of(constraints),
        &params,
        &MotionParams::default(),
        &mut |_| ControlFlow::Continue(()),
    )
    .expect("solves");
    let v = motion.velocities_at(0.0).expect("in span");
    let worst = (0..body.len())
        .map(|i| (body.field().displacement(i, &v) - target).norm())
        .fold(0.0, Real::max);
    println!(
        "velocity at t = 0: worst deviation {worst:.3} m/s from {:?} m/s; {:?}",
        target.as_slice(),
        motion.info
    );
    assert!(
        worst < 0.1 * target.norm(),
        "the field's velocity at t = 0 should be within 10 % of the target, worst deviation \
         {worst:.3} m/s"
    );
}

/// Cancelling stops the solve with an error that says so; the inputs
/// are borrowed immutably, so they cannot have changed.
#[test]
fn cancelling_stops_a_solve() {
    let passage = Passage::default();
    let params = DesignParams::default();
    let body = passage.body(&params).expect("body");
    let mut seen = 0;
    let result = solve_motion(
        &body,
        &passage.constraints(),
        &params,
        &MotionParams::default(),
        &mut |p| {
            seen += 1;
            if p.iteration >= 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    );
    assert!(
        matches!(result, Err(DesignError::Cancelled { iteration: 2 })),
        "{result:?}"
    );
    assert!(seen >= 3);
}
