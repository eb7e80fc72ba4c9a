//! The world's removal masks. Particles marked for removal leave at the
//! start of the next step and not before; frames, particle ids and the
//! solids' ranges follow the new counts, and the survivors carry on from
//! where they were. A system that cannot remove particles says so, and a
//! rejected request marks nothing.

use super::system::RemovalMask;
use super::{RemoveError, World};
use crate::frame::Frame;
use crate::scene::{BuildOptions, Scene, SolverKind, SystemSpec};

/// A 2D tank: a 6 x 6 block of fluid (systems[0]) beside an elastic box
/// (systems[1]), and, with `body`, a floating disc (systems[2]).
fn world(solver: SolverKind, body: bool) -> World {
    let mut text = String::from(
        r#"
        dimension = 2
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = 0.0005
        [[systems]]
        kind = "fluid"
        spacing = 0.05
        stiffness = 1000.0
        [[systems.blocks]]
        region = { min = [0.0, 0.0, 0.0], max = [0.3, 0.3, 0.0] }
        [[systems]]
        kind = "solid"
        shape = { type = "box", half_extents = [0.1, 0.1, 0.1] }
        position = [0.7, 0.5, 0.0]
        spacing = 0.05
        young = 1e5
        "#,
    );
    if body {
        text.push_str(
            r#"
            [[systems]]
            kind = "rigid_body"
            shape = { type = "sphere", radius = 0.05 }
            position = [0.15, 0.2, 0.0]
            motion = "dynamic"
            density = 500.0
            "#,
        );
    }
    let mut scene = Scene::from_toml_str(&text).expect("the scene parses");
    if let SystemSpec::Fluid(fluid) = &mut scene.systems[0] {
        fluid.solver = solver;
    }
    scene
        .build(&BuildOptions::default())
        .expect("the scene is valid")
}

fn fluid_len(world: &World) -> usize {
    world.fluid().expect("a fluid").len()
}

/// Position `k` of a frame's particles.
fn position(frame: &Frame, k: usize) -> [f32; 3] {
    let values = &frame.fields[0].values;
    [values[3 * k], values[3 * k + 1], values[3 * k + 2]]
}

fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f32>()
        .sqrt()
}

/// With either solver: removed particles are still in every frame until
/// the next step, then gone; the survivors are renumbered in order and
/// are where they were (one step of 0.5 ms moves a resting particle by
/// micrometres, a wrong survivor would be a spacing away); the solid's
/// range starts where the smaller fluid ends.
#[test]
fn removed_fluid_particles_leave_at_the_next_step() {
    for solver in [SolverKind::Wcsph, SolverKind::Dfsph] {
        let mut world = world(solver, false);
        let before = world.frame();
        let n = fluid_len(&world);
        assert_eq!(before.solids[0].first, n, "{solver:?}");
        let removed = [0, 7, n - 1];
        world
            .remove_particles(0, &removed)
            .expect("fluid particles");
        assert_eq!(
            world.frame(),
            before,
            "{solver:?}: removal waits for the step"
        );

        world.step().expect("a stable step");
        let after = world.frame();
        assert_eq!(fluid_len(&world), n - 3, "{solver:?}");
        assert_eq!(
            after.particle_count,
            before.particle_count - 3,
            "{solver:?}"
        );
        assert_eq!(after.fields[0].values.len(), 3 * after.particle_count);
        assert_eq!(after.solids[0].first, n - 3, "{solver:?}");
        assert_eq!(after.solids[0].count, before.solids[0].count, "{solver:?}");
        let kept = (0..n).filter(|id| !removed.contains(id));
        for (id, old) in kept.enumerate() {
            let moved = distance(position(&after, id), position(&before, old));
            assert!(
                moved < 1e-3,
                "{solver:?}: survivor {id} (particle {old} before) moved {moved} m in one step"
            );
        }
        for k in 0..before.solids[0].count {
            let moved = distance(position(&after, n - 3 + k), position(&before, n + k));
            assert!(
                moved < 1e-3,
                "{solver:?}: solid particle {k} moved {moved} m"
            );
        }
        for _ in 0..5 {
            world.step().expect("the smaller fluid steps on");
        }
    }
}

/// DFSPH around a floating body: the solver's scratch and the body
/// coupling follow the smaller fluid, which keeps stepping.
#[test]
fn a_fluid_with_a_body_steps_on_after_removals() {
    let mut world = world(SolverKind::Dfsph, true);
    let n = fluid_len(&world);
    let half: Vec<usize> = (0..n).step_by(2).collect();
    world.remove_particles(0, &half).expect("fluid particles");
    for step in 0..10 {
        world
            .step()
            .unwrap_or_else(|e| panic!("step {step} after the removal: {e}"));
    }
    assert_eq!(fluid_len(&world), n - half.len());
    let body = world.body_poses()[0];
    assert!(body.position.iter().all(|x| x.is_finite()), "{body:?}");
}

/// Removing every particle leaves an empty fluid that still steps and
/// frames that carry the solid alone.
#[test]
fn every_fluid_particle_can_go() {
    let mut world = world(SolverKind::Wcsph, false);
    let n = fluid_len(&world);
    let all: Vec<usize> = (0..n).collect();
    world.remove_particles(0, &all).expect("fluid particles");
    world.step().expect("an empty fluid steps");
    let frame = world.frame();
    assert_eq!(fluid_len(&world), 0);
    assert_eq!(frame.solids[0].first, 0);
    assert_eq!(frame.particle_count, frame.solids[0].count);
}

/// A solid cannot remove particles yet, an index that names no particle
/// system is refused, and a request with one bad id marks none of its
/// ids; an empty request changes nothing at all.
#[test]
fn rejected_removals_say_why_and_mark_nothing() {
    let mut world = world(SolverKind::Wcsph, false);
    let n = fluid_len(&world);
    let err = world.remove_particles(1, &[0]).expect_err("a solid");
    assert_eq!(
        err,
        RemoveError::Unsupported {
            system: 1,
            kind: "an elastic solid"
        }
    );
    assert!(err.to_string().contains("cannot remove particles"), "{err}");
    assert_eq!(
        world.remove_particles(5, &[0]),
        Err(RemoveError::NoSystem { system: 5 })
    );
    assert_eq!(
        world.remove_particles(0, &[1, n]),
        Err(RemoveError::NoParticle {
            system: 0,
            particle: n,
            count: n
        })
    );
    world.remove_particles(0, &[]).expect("nothing to remove");
    let mut untouched = self::world(SolverKind::Wcsph, false);
    for _ in 0..2 {
        world.step().expect("a stable step");
        untouched.step().expect("a stable step");
    }
    assert_eq!(fluid_len(&world), n);
    assert_eq!(world.frame(), untouched.frame());
}

/// The mask accumulates marks until taken, and is empty after.
#[test]
fn the_mask_collects_marks_until_taken() {
    let mut mask = RemovalMask::default();
    assert_eq!(mask.take(), None);
    mask.mark(0, 4, &[1]).expect("in range");
    mask.mark(0, 4, &[3, 1]).expect("in range");
    assert_eq!(mask.take(), Some(vec![false, true, false, true]));
    assert_eq!(mask.take(), None);
}
