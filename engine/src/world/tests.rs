//! The world's removal masks. Particles marked for removal leave at the
//! start of the next step and not before; frames, particle ids and the
//! solids' ranges follow the new counts, and the survivors carry on from
//! where they were. A system that cannot remove particles says so, and a
//! rejected request marks nothing.

use super::system::simulated::ParticleChanges;
use super::{ChangeError, InsertError, RemoveError, World};
use crate::frame::{FieldKind, Frame};
use crate::scene::{BuildOptions, Scene, SolverKind, SystemSpec};

/// A 2D tank: a 6 x 6 block of fluid (systems[0]) beside an elastic box
/// (systems[1]), and, with `body`, a floating disc (systems[2]).
fn world(solver: SolverKind, body: bool) -> World {
    scene(solver, body)
        .build(&BuildOptions::default())
        .expect("the scene is valid")
}

/// The scene of [`world`].
fn scene(solver: SolverKind, body: bool) -> Scene {
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
/// the next step, then gone; the survivors keep their order in frames and
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

/// Ids are stable: frames that name the id field list each survivor with
/// the id it was built with, in id order, through removals in two steps
/// and the Z-order sorts between them (every 32 sub-steps); an id gone is
/// refused, a survivor is removed by its own id, and a particle is followed
/// by id from frame to frame.
#[test]
fn particles_keep_their_ids_through_removals_and_sorts() {
    let mut scene = scene(SolverKind::Dfsph, false);
    scene.output.fields.push(FieldKind::Id);
    let mut world = scene.build(&BuildOptions::default()).expect("world");
    let n = fluid_len(&world);
    let ids = |frame: &Frame| frame.ids.clone().expect("ids named");
    let first = world.frame();
    assert_eq!(first.ids.as_ref().map(Vec::len), Some(first.particle_count));
    assert_eq!(ids(&first)[..n], (0..n as u32).collect::<Vec<_>>()[..]);
    let followed = n as u32 / 2;
    world.remove_particles(0, &[0, 3, 9]).expect("live ids");
    for _ in 0..40 {
        world.step().expect("stable");
    }
    let (count, ids_now) = (fluid_len(&world), ids(&world.frame()));
    assert_eq!(count, n - 3);
    let expected: Vec<u32> = (0..n as u32).filter(|id| ![0, 3, 9].contains(id)).collect();
    assert_eq!(
        ids_now[..count],
        expected[..],
        "survivors keep their ids, in id order"
    );
    assert_eq!(
        world.remove_particles(0, &[3]),
        Err(RemoveError::NoParticle {
            system: 0,
            particle: 3,
            count: n
        }),
        "an id gone names no particle"
    );
    let before = world.frame();
    let at = |frame: &Frame, id: u32| {
        let row = ids(frame).iter().position(|&k| k == id).expect("listed");
        assert!(row < frame.solids[0].first, "a fluid row");
        position(frame, row)
    };
    world.remove_particles(0, &[4, n - 1]).expect("live ids");
    world.step().expect("stable");
    let after = world.frame();
    assert_eq!(fluid_len(&world), n - 5);
    // The fluid's rows come first; the solid's ids are its own.
    let fluid_ids = &ids(&after)[..n - 5];
    assert!(!fluid_ids.contains(&4) && !fluid_ids.contains(&(n as u32 - 1)));
    assert_eq!(ids(&after)[n - 5..], ids(&first)[n..], "the solid's ids");
    let moved = distance(at(&after, followed), at(&before, followed));
    assert!(
        moved < 1e-3,
        "particle {followed} followed by id moved {moved} m"
    );
    assert_eq!(world.fluid().expect("fluid").next_id(), n as u32);
}

/// Particles come and go in one run: a fluid takes new particles (up to
/// the count it was built with) after removals, they get the next ids and
/// join at the next step where they were put; bad ones are refused with
/// nothing queued; a solid takes none; a snapshot taken with changes
/// queued restores and continues bit for bit.
#[test]
fn new_particles_join_at_the_next_step_with_the_next_ids() {
    let mut scene = scene(SolverKind::Dfsph, false);
    scene.output.fields.push(FieldKind::Id);
    let mut world = scene.build(&BuildOptions::default()).expect("world");
    let n = fluid_len(&world);
    assert!(
        matches!(
            world.insert_particles(0, &[[0.5, 0.9, 0.0]], &[[0.0; 3]]),
            Err(InsertError::Capacity { capacity, .. }) if capacity == n
        ),
        "a full fluid takes none"
    );
    world.remove_particles(0, &[1, 2]).expect("live ids");
    let refused = [
        world.insert_particles(0, &[[2.0, 0.5, 0.0]], &[[0.0; 3]]),
        world.insert_particles(0, &[[0.5, 0.9, 0.0]], &[[f64::NAN, 0.0, 0.0]]),
        world.insert_particles(0, &[[0.5, 0.9, 0.0]], &[]),
        world.insert_particles(0, &[[0.5, 0.9, 0.0]; 3], &[[0.0; 3]; 3]),
        world.insert_particles(1, &[[0.5, 0.9, 0.0]], &[[0.0; 3]]),
        world.insert_particles(7, &[[0.5, 0.9, 0.0]], &[[0.0; 3]]),
    ];
    let messages: Vec<String> = refused
        .iter()
        .map(|r| r.as_ref().err().map(ToString::to_string).expect("refused"))
        .collect();
    assert!(
        messages[0].contains("outside the domain"),
        "{}",
        messages[0]
    );
    assert!(messages[1].contains("not finite"), "{}", messages[1]);
    assert!(messages[2].contains("one velocity per"), "{}", messages[2]);
    assert!(messages[3].contains("more than the"), "{}", messages[3]);
    assert!(
        messages[4].contains("cannot take new particles"),
        "{}",
        messages[4]
    );
    assert!(
        messages[5].contains("not a particle system"),
        "{}",
        messages[5]
    );
    let ids = world
        .insert_particles(
            0,
            &[[0.5, 0.9, 0.0], [0.55, 0.9, 0.0]],
            &[[0.0, -1.0, 0.0]; 2],
        )
        .expect("room for two after two removals");
    assert_eq!(ids, n as u32..n as u32 + 2);
    // A snapshot with the changes queued continues as the world does.
    let state = world.state();
    let mut restored = scene
        .build(&BuildOptions::default())
        .expect("world")
        .restored(&state)
        .expect("restores");
    for _ in 0..3 {
        world.step().expect("stable");
        restored.step().expect("stable");
        assert_eq!(world.frame(), restored.frame(), "bit for bit");
    }
    let frame = world.frame();
    assert_eq!(fluid_len(&world), n);
    let fluid_ids = &frame.ids.as_ref().expect("ids")[..n];
    assert_eq!(
        fluid_ids[n - 2..],
        [n as u32, n as u32 + 1],
        "new ids rank last"
    );
    assert!(!fluid_ids.contains(&1) && !fluid_ids.contains(&2));
    let y = position(&frame, n - 2)[1];
    assert!(
        (0.8..0.9).contains(&y),
        "the new particle falls from 0.9 m: {y}"
    );
}

/// A change of particles is all or nothing: a removal with a refused
/// insertion queues neither, and the removal makes room for the insertion
/// of the same request.
#[test]
fn a_change_of_particles_is_all_or_nothing() {
    let mut world = world(SolverKind::Dfsph, false);
    let n = fluid_len(&world);
    let outside = world.change_particles(0, &[1, 2], &[[2.0, 0.5, 0.0]], &[[0.0; 3]]);
    assert!(
        matches!(
            outside,
            Err(ChangeError::Insert(InsertError::Invalid { .. }))
        ),
        "{outside:?}"
    );
    let unknown = world.change_particles(0, &[1, n + 5], &[], &[]);
    assert!(
        matches!(
            unknown,
            Err(ChangeError::Remove(RemoveError::NoParticle { .. }))
        ),
        "{unknown:?}"
    );
    world.step().expect("stable");
    assert_eq!(fluid_len(&world), n, "nothing was removed");
    let ids = world
        .change_particles(0, &[1], &[[0.5, 0.9, 0.0]], &[[0.0; 3]])
        .expect("the removal frees room for the new particle");
    assert_eq!(ids, n as u32..n as u32 + 1);
    world.step().expect("stable");
    assert_eq!(fluid_len(&world), n);
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
    let mut mask = ParticleChanges::default();
    assert!(mask.take().is_empty());
    mask.mark(0, 4, &[1]).expect("in range");
    mask.mark(0, 4, &[3, 1]).expect("in range");
    assert_eq!(mask.take().marked_ids(), vec![1, 3]);
    assert!(mask.take().is_empty());
}

/// Modal EFG solids in a world: built from a scene, stepped, listed in
/// frames with their skin, grabbed, snapshotted and played back.
mod modal {
    use crate::efg::Grab;
    use crate::math::{Real, Vector};
    use crate::scene::{BuildOptions, Scene, SceneError};
    use crate::world::{Control, ControlError, ControlKind, Controls, World};

    /// A 16 x 4 x 4 cm cantilever on 2 cm cells (a few hundred nodes),
    /// clamped at x = 0, with `extra` appended to its system table.
    fn scene(extra: &str) -> Scene {
        let text = format!(
            r#"
            [domain]
            min = [-0.05, -0.3, -0.1]
            max = [0.3, 0.1, 0.1]
            [time]
            dt = 0.02
            [output]
            fields = ["velocity", "elastic_energy", "mass"]
            [[systems]]
            kind = "modal_solid"
            shape = {{ type = "box", half_extents = [0.08, 0.02, 0.02] }}
            position = [0.08, 0.0, 0.0]
            young = 1e5
            cell = 0.02
            modes = 12
            mass_damping = 2.0
            surface_subdivisions = 2
            anchors = [{{ min = [-0.001, -0.03, -0.03], max = [0.001, 0.03, 0.03] }}]
            {extra}
            "#
        );
        Scene::from_toml_str(&text).expect("the scene parses")
    }

    fn world(extra: &str) -> World {
        scene(extra)
            .build(&BuildOptions::default())
            .expect("the scene is valid")
    }

    /// Controls holding `grabs` on system `system`, named `grab-0`, ...
    fn grabs(system: usize, grabs: &[Grab]) -> Controls {
        let mut controls = Controls::new();
        for (k, &g) in grabs.iter().enumerate() {
            let control = Control {
                system,
                kind: ControlKind::Grab(g),
            };
            controls.insert(format!("grab-{k}"), control);
        }
        controls
    }

    fn tip(world: &World) -> Vector {
        let frame = world.frame();
        let positions = &frame.fields[0].values;
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        // The node with the largest rest x at mid-height.
        let (k, _) = solid
            .rest_positions()
            .iter()
            .enumerate()
            .max_by(|a, b| (a.1.x - a.1.y.abs()).total_cmp(&(b.1.x - b.1.y.abs())))
            .expect("nodes");
        Vector::new(
            positions[3 * k] as Real,
            positions[3 * k + 1] as Real,
            positions[3 * k + 2] as Real,
        )
    }

    #[test]
    fn a_cancelled_check_stops_the_precompute_with_its_own_error() {
        let options = BuildOptions::default();
        options.cancel.cancel();
        assert_eq!(
            scene("").check(&options).err(),
            Some(SceneError::Cancelled),
            "a raised flag ends the modal solid's precompute"
        );
    }

    #[test]
    fn a_clamped_beam_sags_and_its_frames_carry_nodes_and_skin() {
        let mut world = world("");
        let frame = world.frame();
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        let nodes = solid.len();
        assert_eq!(frame.particle_count, nodes);
        assert_eq!(frame.solids.len(), 1);
        assert_eq!(frame.solids[0].count, nodes);
        let rest_tip = tip(&world);
        for _ in 0..100 {
            world.step().expect("a stable step");
        }
        let sagged = tip(&world);
        assert!(
            sagged.y < rest_tip.y - 1e-3,
            "the tip sags: {rest_tip:?} -> {sagged:?}"
        );
        let frame = world.frame();
        let skin = &frame.solid_surfaces[0];
        assert_eq!(skin.system, 0);
        assert_eq!(skin.mesh.triangles.len(), 12 * 16);
        assert!(
            // Normalised in f32, as frames ship them.
            skin.normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-6),
            "unit normals"
        );
        let lowest = skin
            .mesh
            .vertices
            .iter()
            .map(|v| v.y)
            .fold(Real::INFINITY, Real::min);
        assert!(lowest < -0.02 - 1e-3, "the skin sags with the nodes");
        let energy: f32 = frame
            .field(crate::frame::FieldKind::ElasticEnergy)
            .expect("asked for")
            .values
            .iter()
            .sum();
        assert!(energy > 0.0, "a bent beam stores energy");
        let mass: f32 = frame
            .field(crate::frame::FieldKind::Mass)
            .expect("asked for")
            .values
            .iter()
            .sum();
        let exact = 1000.0 * 0.16 * 0.04 * 0.04;
        assert!(
            ((mass as Real) - exact).abs() < 0.02 * exact,
            "node masses sum to the beam's {exact} kg: {mass}"
        );
    }

    #[test]
    fn a_grabbed_tip_goes_where_it_is_told_and_a_bad_grab_changes_nothing() {
        let mut world = world("");
        let point = Vector::new(0.16, 0.0, 0.0);
        let target = Vector::new(0.15, 0.05, 0.0);
        world
            .set_controls(grabs(
                0,
                &[Grab {
                    point,
                    position: Some(target),
                    rotation: None,
                }],
            ))
            .expect("a valid grab");
        for _ in 0..60 {
            world.step().expect("a stable step");
        }
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        assert!(
            solid.grab_violation() < 1e-4,
            "the grab is met: {}",
            solid.grab_violation()
        );
        let table = solid
            .efg()
            .shape_table(&[point])
            .expect("the point is covered");
        let mut u = Vec::new();
        table.interpolate(solid.displacements(), &mut u);
        let held = point + u[0];
        println!("grabbed point at {held:?}, target {target:?}");
        assert!(
            (held - target).norm() < 1e-3 * (target - point).norm(),
            "the warped point follows the grab: {held:?} vs {target:?}"
        );
        let before = world.state();
        let outside = Grab {
            point: Vector::new(2.0, 0.0, 0.0),
            position: Some(target),
            rotation: None,
        };
        assert!(matches!(
            world.set_controls(grabs(0, &[outside])),
            Err(ControlError::Grab { system: 0, ref name, .. }) if name == "grab-0"
        ));
        assert!(matches!(
            world.set_controls(grabs(3, &[outside])),
            Err(ControlError::NotGrabbable { system: 3, .. })
        ));
        let empty = Grab {
            point,
            position: None,
            rotation: None,
        };
        assert!(world.set_controls(grabs(0, &[empty])).is_err());
        assert_eq!(world.controls().len(), 1, "the earlier control stays");
        assert_eq!(world.state(), before);
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        assert_eq!(solid.grabs().len(), 1, "the earlier grab stays");
    }

    #[test]
    fn a_snapshot_restores_the_modal_state_bit_for_bit() {
        let mut a = world("");
        for _ in 0..5 {
            a.step().expect("a stable step");
        }
        let state = a.state();
        let b = world("").restored(&state).expect("same scene");
        let mut a2 = a.clone();
        let mut b2 = b;
        a2.step().expect("a stable step");
        b2.step().expect("a stable step");
        assert_eq!(a2.frame(), b2.frame());
    }

    /// `dynamics = "nonlinear"` on the same cantilever (soft: its linear
    /// sag is over a third of its length): no modes, the full state steps
    /// and sags, frames carry its skin and St Venant–Kirchhoff energy, a
    /// snapshot carries the full state bit for bit, a position grab holds
    /// as a spring, and what needs modes (playback, posing, orientation
    /// grabs) is refused by name.
    #[test]
    fn nonlinear_dynamics_steps_the_full_state_and_refuses_what_needs_modes() {
        use crate::efg::Dynamics;
        let nonlinear = "dynamics = \"nonlinear\"";
        let mut world = world(nonlinear);
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        assert_eq!(solid.dynamics(), Dynamics::Nonlinear);
        assert!(solid.eigenvalues().is_empty(), "no modes are computed");
        assert_eq!(solid.state_len(), 3 * solid.len());
        let rest_tip = tip(&world);
        for _ in 0..5 {
            world.step().expect("a stable step");
        }
        let state = world.state();
        let mut again = world.clone();
        let mut restored = self::world(nonlinear).restored(&state).expect("same scene");
        again.step().expect("a stable step");
        restored.step().expect("a stable step");
        assert_eq!(again.frame(), restored.frame(), "the full state restores");
        for _ in 0..45 {
            world.step().expect("a stable step");
        }
        let frame = world.frame();
        assert_eq!(frame.unconverged, 0, "every Newton solve converged");
        let sagged = tip(&world);
        println!("nonlinear tip {rest_tip:?} -> {sagged:?}");
        assert!(sagged.y < rest_tip.y - 0.02, "the tip sags: {sagged:?}");
        // It swings down, so the tip comes closer to the clamp: a
        // rotation the linear strain would have stretched instead.
        assert!(sagged.x < rest_tip.x - 2e-3, "{sagged:?}");
        let energy: f32 = frame
            .field(crate::frame::FieldKind::ElasticEnergy)
            .expect("asked for")
            .values
            .iter()
            .sum();
        assert!(energy > 0.0, "a bent beam stores energy");
        let skin = &frame.solid_surfaces[0];
        assert!(skin.normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-6));
        let point = Vector::new(0.16, 0.0, 0.0);
        let target = Vector::new(0.15, 0.03, 0.0);
        world
            .set_controls(grabs(
                0,
                &[Grab {
                    point,
                    position: Some(target),
                    rotation: None,
                }],
            ))
            .expect("a position grab");
        for _ in 0..40 {
            world.step().expect("a stable step");
        }
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        let table = solid.efg().shape_table(&[point]).expect("covered");
        let mut u = Vec::new();
        table.interpolate(solid.displacements(), &mut u);
        let held = point + u[0];
        println!("nonlinear grab: {held:?}, target {target:?}");
        assert!(
            (held - target).norm() < 0.02 * (target - point).norm(),
            "the spring holds the point: {held:?} vs {target:?}"
        );
        let turn = Grab {
            point,
            position: None,
            rotation: Some(Vector::new(0.0, 0.0, 0.3)),
        };
        let refused = world
            .set_controls(grabs(0, &[turn]))
            .expect_err("no orientation grabs");
        assert!(refused.to_string().contains("dynamics"), "{refused}");
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        let mut posed = solid.clone();
        let error = posed.pose_mode(0, 1.0).expect_err("no modes to pose");
        assert!(error.to_string().contains("dynamics"), "{error}");
        let error = scene(&format!(
            "{nonlinear}\nplayback = {{ mode = 0, amplitude = 0.5 }}"
        ))
        .validate(&BuildOptions::default())
        .expect_err("playback needs modes");
        assert!(
            error.to_string().starts_with("systems[0].playback"),
            "{error}"
        );
    }

    #[test]
    fn playback_poses_a_mode_shape() {
        let mut world = world("playback = { mode = 0, amplitude = 0.5 }");
        world.step().expect("a pose");
        let frame = world.frame();
        let (_, solid) = world.modal_solids().next().expect("a modal solid");
        let omega = solid.frequencies()[0];
        let expected = 0.5 * (omega * 0.02).sin();
        let z = solid.state().amplitudes;
        assert!((z[0] - expected).abs() < 1e-12, "{} vs {expected}", z[0]);
        assert!(z[1..].iter().all(|v| *v == 0.0));
        assert_eq!(frame.step, 1);
    }

    #[test]
    fn bad_modal_scenes_name_the_field_at_fault() {
        use crate::scene::{ModalSolidSpec, PlaybackSpec, SystemSpec};
        let options = BuildOptions::default();
        type Change<'a> = &'a dyn Fn(&mut ModalSolidSpec);
        let cases: [(Change, &str); 6] = [
            (&|s| s.alpha = 1.0, "systems[0].alpha"),
            (&|s| s.modes = 0, "systems[0].modes"),
            (&|s| s.quadrature_order = 9, "systems[0].quadrature_order"),
            (
                &|s| {
                    s.playback = Some(PlaybackSpec {
                        mode: 40,
                        amplitude: 1.0,
                    })
                },
                "systems[0].playback.mode",
            ),
            (&|s| s.grab_gamma = -1.0, "systems[0].grab_gamma"),
            (&|s| s.anchors[0].min[0] = 0.5, "systems[0].anchors[0]"),
        ];
        for (change, field) in cases {
            let mut bad = scene("");
            let SystemSpec::ModalSolid(spec) = &mut bad.systems[0] else {
                panic!("a modal solid");
            };
            change(spec);
            let error = bad.validate(&options).expect_err(field);
            assert!(error.to_string().starts_with(field), "{field}: {error}");
        }
        let mut fine = scene("");
        if let SystemSpec::ModalSolid(s) = &mut fine.systems[0] {
            s.cell = 1e-4;
        }
        assert!(matches!(
            fine.validate(&options),
            Err(crate::scene::SceneError::TooFine { .. })
        ));
    }

    /// A point cloud (a PLY of 400 points with outward normals on a 5 cm
    /// sphere, no faces) builds a free modal solid: six rigid modes, its
    /// skin the points with unit normals and no triangles.
    #[test]
    fn an_oriented_point_cloud_builds_a_free_modal_solid() {
        use crate::geometry::read::MeshFormat;
        use crate::scene::{MeshData, ShapeSpec, SystemSpec};
        let count = 400;
        let mut ply = format!(
            "ply\nformat ascii 1.0\nelement vertex {count}\nproperty float x\n\
             property float y\nproperty float z\nproperty float nx\nproperty float ny\n\
             property float nz\nend_header\n"
        );
        for n in crate::testing::fibonacci_sphere(count) {
            let p = n * 0.05;
            ply.push_str(&format!(
                "{} {} {} {} {} {}\n",
                p.x, p.y, p.z, n.x, n.y, n.z
            ));
        }
        let mut scene = scene("");
        let SystemSpec::ModalSolid(spec) = &mut scene.systems[0] else {
            panic!("a modal solid");
        };
        spec.shape = ShapeSpec::Mesh {
            path: None,
            data: Some(MeshData {
                format: MeshFormat::Ply,
                content: ply.into_bytes(),
            }),
            scale: None,
        };
        spec.anchors.clear();
        for dynamics in [crate::efg::Dynamics::Modal, crate::efg::Dynamics::Nonlinear] {
            let SystemSpec::ModalSolid(spec) = &mut scene.systems[0] else {
                panic!("a modal solid");
            };
            spec.dynamics = dynamics;
            let mut world = scene
                .build(&BuildOptions::default())
                .expect("a point cloud builds");
            let (_, solid) = world.modal_solids().next().expect("a modal solid");
            if dynamics == crate::efg::Dynamics::Modal {
                assert_eq!(solid.zero_modes(), 6, "a free body");
            }
            world.step().expect("a stable step");
            let frame = world.frame();
            let skin = &frame.solid_surfaces[0];
            assert_eq!(skin.mesh.vertices.len(), count);
            assert!(skin.mesh.triangles.is_empty(), "surfels, no triangles");
            assert!(
                skin.normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-9),
                "{dynamics:?}: unit normals"
            );
            // A free ball falls undeformed: its normals (under nonlinear
            // dynamics F^-T n, F = I) keep their rest directions.
            for (n, rest) in skin
                .normals
                .iter()
                .zip(crate::testing::fibonacci_sphere(count))
            {
                assert!(n.dot(&rest) > 1.0 - 1e-6, "{dynamics:?}: {n:?} vs {rest:?}");
            }
        }
    }
}
