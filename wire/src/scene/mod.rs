//! Conversions of the scene messages (`scene.proto`): the scene spec,
//! both directions, with one file per system kind (`fluid.rs`, `solid.rs`,
//! `body.rs`, `modal.rs`, `shell.rs`) and the vectors, boxes and shapes they share
//! (`geometry.rs`, a leaf). Each file holds the tables of the enums its
//! messages declare. Unset optional fields take the scene file's defaults,
//! so both front doors (TOML and gRPC) build the same scene; ranges are
//! checked later by `Scene::validate`, with the same field names.
//!
//! A new system kind adds its file here and one arm in each of
//! [`scene_from_proto`] (through `system_from_proto`), [`scene_to_proto`]
//! and [`scene_echo_to_proto`].

mod body;
mod fluid;
mod geometry;
mod modal;
mod shell;
mod solid;

pub(crate) use geometry::{aabb, shape_from_proto, to_aabb, to_shape, to_vec3, vec3};

use crate::enums::{WireEnum, required_enum, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use meshless_engine::scene::{OutputSpec, SurfaceSpec, SystemSpec, TimeSpec, defaults};
use meshless_engine::{FieldKind, Scene};
use meshless_proto::v1;

wire_enum! {
    /// The fields a frame can carry (`output.fields`, frame headers).
    FieldKind <-> FieldKind, "field kind" {
        "position" => Position,
        "velocity" => Velocity,
        "density" => Density,
        "pressure" => Pressure,
        "mass" => Mass,
        "volume" => Volume,
        "kinetic_energy" => KineticEnergy,
        "elastic_energy" => ElasticEnergy,
        "id" => Id,
        "fragment" => Fragment,
    }
}

/// The engine scene of a `SceneSpec`; unset optional fields take the
/// scene file's defaults, and ranges are checked later by
/// `Scene::validate`, with the same field names.
pub fn scene_from_proto(spec: v1::SceneSpec) -> Result<Scene> {
    let v1::SceneSpec {
        name,
        domain,
        gravity,
        time,
        systems,
        output,
        dimension,
        periodic,
    } = spec;
    let v1::TimeSpec {
        dt,
        max_substeps,
        cfl,
    } = required(time, "time")?;
    let systems = systems
        .into_iter()
        .enumerate()
        .map(|(s, system)| system_from_proto(system, &format!("systems[{s}]")))
        .collect::<Result<Vec<_>>>()?;
    let output = match output {
        None => OutputSpec::default(),
        Some(v1::OutputSpec {
            fields,
            frame_every,
            surface,
        }) => OutputSpec {
            fields: fields
                .into_iter()
                .enumerate()
                .map(|(i, f)| required_enum::<FieldKind>(f, &format!("output.fields[{i}]")))
                .collect::<Result<_>>()?,
            frame_every: frame_every.unwrap_or(defaults::FRAME_EVERY),
            surface: surface.map(|surface| {
                let v1::SurfaceSpec { cell, iso } = surface;
                SurfaceSpec {
                    cell,
                    iso: iso.unwrap_or(defaults::SURFACE_ISO),
                }
            }),
        },
    };
    Ok(Scene {
        name,
        dimension: dimension.map_or(3, |d| d as usize),
        domain: aabb(domain, "domain")?,
        periodic: periodic.map_or([false; 3], |v1::Periodic { x, y, z }| [x, y, z]),
        gravity: gravity.map_or(defaults::GRAVITY, vec3),
        time: TimeSpec {
            dt,
            max_substeps: max_substeps.unwrap_or(defaults::MAX_SUBSTEPS),
            cfl: cfl.unwrap_or(defaults::CFL),
        },
        systems,
        output,
    })
}

fn system_from_proto(system: v1::SystemSpec, field: &str) -> Result<SystemSpec> {
    let v1::SystemSpec { kind } = system;
    match kind {
        Some(v1::system_spec::Kind::Fluid(fluid)) => {
            Ok(SystemSpec::Fluid(fluid::fluid_from_proto(fluid, field)?))
        }
        Some(v1::system_spec::Kind::RigidBody(body)) => {
            Ok(SystemSpec::RigidBody(body::body_from_proto(body, field)?))
        }
        Some(v1::system_spec::Kind::Solid(solid)) => {
            Ok(SystemSpec::Solid(solid::solid_from_proto(solid, field)?))
        }
        Some(v1::system_spec::Kind::ModalSolid(solid)) => Ok(SystemSpec::ModalSolid(
            modal::modal_from_proto(solid, field)?,
        )),
        Some(v1::system_spec::Kind::Shell(shell)) => {
            Ok(SystemSpec::Shell(shell::shell_from_proto(shell, field)?))
        }
        None => Err(WireError::new(
            format!("{field}.kind"),
            "unknown or missing system kind; this server simulates: fluid, rigid_body, solid, \
             modal_solid, shell",
        )),
    }
}

/// The `SceneSpec` of an engine scene, every default made explicit.
pub fn scene_to_proto(scene: &Scene) -> v1::SceneSpec {
    v1::SceneSpec {
        name: scene.name.clone(),
        dimension: Some(scene.dimension as u32),
        domain: Some(to_aabb(&scene.domain)),
        periodic: scene.periodic.contains(&true).then_some(v1::Periodic {
            x: scene.periodic[0],
            y: scene.periodic[1],
            z: scene.periodic[2],
        }),
        gravity: Some(to_vec3(scene.gravity)),
        time: Some(v1::TimeSpec {
            dt: scene.time.dt,
            max_substeps: Some(scene.time.max_substeps),
            cfl: Some(scene.time.cfl),
        }),
        systems: scene
            .systems
            .iter()
            .map(|system| v1::SystemSpec {
                kind: Some(match system {
                    SystemSpec::Fluid(f) => v1::system_spec::Kind::Fluid(fluid::to_fluid(f)),
                    SystemSpec::RigidBody(b) => v1::system_spec::Kind::RigidBody(body::to_body(b)),
                    SystemSpec::Solid(s) => v1::system_spec::Kind::Solid(solid::to_solid(s)),
                    SystemSpec::ModalSolid(s) => {
                        v1::system_spec::Kind::ModalSolid(modal::to_modal(s))
                    }
                    SystemSpec::Shell(s) => v1::system_spec::Kind::Shell(shell::to_shell(s)),
                }),
            })
            .collect(),
        output: Some(v1::OutputSpec {
            fields: scene.output.fields.iter().map(|&k| k.to_i32()).collect(),
            frame_every: Some(scene.output.frame_every),
            surface: scene.output.surface.as_ref().map(|surface| {
                let spacing = scene.fluid().map(|f| f.spacing);
                v1::SurfaceSpec {
                    cell: spacing.map_or(surface.cell, |dx| Some(surface.cell(dx))),
                    iso: Some(surface.iso),
                }
            }),
        }),
    }
}

/// The scene as a server echoes it (`Session.scene`): [`scene_to_proto`]
/// with every mesh's bytes left out and their length given instead, so
/// that getting or listing sessions never sends their meshes back.
pub fn scene_echo_to_proto(scene: &Scene) -> v1::SceneSpec {
    let mut spec = scene_to_proto(scene);
    for system in &mut spec.systems {
        let shape = match &mut system.kind {
            Some(v1::system_spec::Kind::RigidBody(body)) => body.shape.as_mut(),
            Some(v1::system_spec::Kind::Solid(solid)) => solid.shape.as_mut(),
            Some(v1::system_spec::Kind::ModalSolid(solid)) => solid.shape.as_mut(),
            Some(v1::system_spec::Kind::Shell(shell)) => shell.shape.as_mut(),
            Some(v1::system_spec::Kind::Fluid(_)) | None => None,
        };
        if let Some(v1::Shape {
            kind:
                Some(v1::shape::Kind::Mesh(v1::MeshShape {
                    data: Some(data), ..
                })),
        }) = shape
        {
            data.length = data.content.len() as u64;
            data.content = Vec::new();
        }
    }
    spec
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::frame_to_proto;
    use meshless_engine::BuildOptions;
    use meshless_engine::approx::mls::Order;
    use meshless_engine::scene::{
        Aabb, IntegratorKind, NotchSpec, ParticleSpec, RigidBodySpec, ShapeSpec, SolidSpec,
        SolidSurfaceSpec,
    };
    use meshless_engine::solid::embedded::EmbeddingMethod;
    use meshless_engine::solid::fracture::Resampling;
    use meshless_engine::solid::{ImplicitParams, ImplicitScheme, LinearSolver, Plasticity};

    fn dam_break() -> Scene {
        Scene::from_toml_str(include_str!("../../../scenes/dam_break.toml")).expect("shipped scene")
    }

    /// engine -> proto -> engine is the identity once defaults are explicit.
    #[test]
    fn scenes_round_trip_through_the_protocol() {
        let scene = dam_break();
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        let mut explicit = scene.clone();
        let SystemSpec::Fluid(f) = &mut explicit.systems[0] else {
            panic!("the first system is the fluid")
        };
        f.support_radius = Some(f.support_radius());
        assert_eq!(back, explicit);
        back.validate(&BuildOptions::default())
            .expect("still valid");

        // Periodic axes and single particles survive the trip too.
        let mut scene = explicit;
        scene.periodic = [true, false, true];
        let SystemSpec::Fluid(f) = &mut scene.systems[0] else {
            panic!("the dam break is a fluid")
        };
        f.particles.push(ParticleSpec {
            position: [3.5, 0.5, 0.5],
            velocity: [-1.0, 0.0, 0.25],
        });
        assert_eq!(
            scene_from_proto(scene_to_proto(&scene)).expect("round trip"),
            scene
        );
    }

    /// Rigid bodies survive engine -> proto -> engine, and frames carry
    /// their poses.
    #[test]
    fn bodies_round_trip_and_frames_carry_poses() {
        let scene = Scene::from_toml_str(include_str!("../../../scenes/floating_box.toml"))
            .expect("shipped scene");
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back.systems[1..], scene.systems[1..]);
        let world = back.build(&BuildOptions::default()).expect("valid");
        let wire = frame_to_proto("s", &world.frame());
        assert_eq!(wire.bodies.len(), 2);
        assert_eq!(wire.bodies[0].system, 1);
        let q = wire.bodies[0].orientation.expect("orientation");
        assert!((q.z - 0.15f64.sin()).abs() < 1e-12 && (q.w - 0.15f64.cos()).abs() < 1e-12);

        let mut spec = scene_to_proto(&scene);
        if let Some(v1::system_spec::Kind::RigidBody(b)) = &mut spec.systems[1].kind {
            b.shape = None;
        }
        let err = scene_from_proto(spec).expect_err("no shape");
        assert!(err.to_string().starts_with("systems[1].shape:"), "{err}");
    }

    /// Mesh shapes cross with their path and scale (the path as the
    /// scene file's directory made it), and the world built from the wire
    /// reads the same files.
    #[test]
    fn mesh_bodies_round_trip() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/mesh_body.toml");
        let scene = Scene::from_toml_file(&path).expect("shipped scene");
        assert!(matches!(
            &scene.systems[1],
            SystemSpec::RigidBody(RigidBodySpec { shape: ShapeSpec::Mesh { scale: Some(s), .. }, .. })
                if *s == 0.06
        ));
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back.systems[1..], scene.systems[1..]);
        let world = back.build(&BuildOptions::default()).expect("valid");
        assert_eq!(frame_to_proto("s", &world.frame()).bodies.len(), 2);

        // Loaded, the bytes cross too, and a host that reads no file
        // builds the same world from them.
        let mut loaded = scene.clone();
        loaded
            .load_meshes(&BuildOptions::default())
            .expect("the shipped meshes load");
        let back = scene_from_proto(scene_to_proto(&loaded)).expect("round trip");
        assert!(
            back.systems[1..] == loaded.systems[1..],
            "the meshes changed"
        );
        let no_files = BuildOptions {
            mesh_files: meshless_engine::scene::MeshFiles::None,
            ..BuildOptions::default()
        };
        let world = back.build(&no_files).expect("built from the bytes");
        assert_eq!(frame_to_proto("s", &world.frame()).bodies.len(), 2);
        let err = scene.build(&no_files).expect_err("paths need files");
        assert!(err.to_string().contains("`data`"), "{err}");

        // The echo leaves the bytes out and says how many there were.
        let echo = scene_echo_to_proto(&loaded);
        let Some(v1::system_spec::Kind::RigidBody(body)) = &echo.systems[1].kind else {
            panic!("a body");
        };
        let Some(v1::Shape {
            kind: Some(v1::shape::Kind::Mesh(mesh)),
        }) = &body.shape
        else {
            panic!("a mesh");
        };
        let data = mesh.data.as_ref().expect("data");
        assert!(data.content.is_empty());
        assert!(data.length > 100, "{}", data.length);
        assert!(mesh.path.ends_with("icosphere.obj"), "{}", mesh.path);
    }

    fn shipped(name: &str) -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(name);
        Scene::from_toml_file(&path).expect("shipped scene")
    }

    /// Solids survive engine -> proto -> engine with every field set away
    /// from its default, and frames say where their particles are.
    #[test]
    fn solids_round_trip_and_frames_carry_their_ranges() {
        for name in ["elastic_beam.toml", "jelly_drop.toml", "brittle_beam.toml"] {
            let scene = shipped(name);
            let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
            assert_eq!(back, scene, "{name}");
        }

        // A toughness, notches and a surface cell cross too.
        let mut scene = shipped("brittle_beam.toml");
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("the beam is a solid")
        };
        let fracture = solid.fracture.as_mut().expect("the beam fractures");
        fracture.toughness = Some(1e5);
        fracture.branching = Some(2.0);
        fracture.surface_cell = 0.3;
        fracture.resample = Some(Resampling {
            q_min: 8.0,
            min_radius_ratio: 0.4,
            max_particles: Some(12_345),
        });
        fracture.notches = vec![
            NotchSpec {
                center: [0.1, 0.02, 0.0],
                normal: [1.0, 0.0, 0.0],
                radius: 0.03,
            },
            NotchSpec {
                center: [0.5, -0.02, 0.0],
                normal: [0.6, 0.8, 0.0],
                radius: 0.01,
            },
        ];
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene);

        // A surface crosses with its method and subdivisions, and frames
        // carry it deformed, with a normal per vertex.
        let mut scene = shipped("jelly_drop.toml");
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("the jelly is a solid")
        };
        solid.surface = Some(SolidSurfaceSpec {
            method: EmbeddingMethod::Gradients,
            subdivisions: 2,
        });
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene);
        let frame = back.build(&BuildOptions::default()).expect("valid").frame();
        let [surface] = &frame.solid_surfaces[..] else {
            panic!("one solid surface")
        };
        let wire = frame_to_proto("s", &frame);
        let [
            v1::SolidSurface {
                system: 0,
                mesh: Some(mesh),
            },
        ] = &wire.solid_surfaces[..]
        else {
            panic!(
                "the jelly's surface on the wire: {:?}",
                wire.solid_surfaces.len()
            )
        };
        assert_eq!(mesh.vertices.len(), 12 * surface.mesh.vertices.len());
        assert_eq!(mesh.normals.len(), mesh.vertices.len());
        assert_eq!(mesh.triangles.len(), 12 * surface.mesh.triangles.len());
        let last = surface.normals.len() - 1;
        let ny = f32::from_le_bytes(
            mesh.normals[12 * last + 4..12 * last + 8]
                .try_into()
                .expect("4 bytes"),
        );
        assert_eq!(ny, surface.normals[last].y as f32);

        let mut scene = shipped("jelly_drop.toml");
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("the jelly is a solid")
        };
        *solid = SolidSpec {
            shape: ShapeSpec::Capsule {
                half_length: 0.05,
                radius: 0.08,
            },
            orientation: [0.1, -0.2, 0.3],
            density: 1200.0,
            poisson: 0.45,
            order: Order::Quadratic,
            support: 2.5,
            hourglass: 0.3,
            friction: 0.1,
            integrator: IntegratorKind::Implicit,
            cfl: 0.25,
            implicit: ImplicitParams {
                newton_tolerance: 1e-4,
                max_newton_iterations: 7,
                cg_tolerance: 1e-2,
                max_cg_iterations: 33,
                linear_solver: LinearSolver::ConjugateGradient,
                scheme: ImplicitScheme::Midpoint,
            },
            velocity: [1.0, 2.0, 3.0],
            angular_velocity: [-1.0, 0.5, 0.25],
            anchors: vec![Aabb {
                min: [0.4, 0.6, 0.4],
                max: [0.6, 0.7, 0.6],
            }],
            plasticity: Some(Plasticity {
                yield_strain: 0.01,
                creep: 0.2,
                max: 0.5,
                rebase: Some(0.3),
            }),
            // A capsule has no surface to embed; the jelly's crossed above.
            surface: None,
            ..solid.clone()
        };
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene);
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("a solid")
        };
        solid.plasticity.as_mut().expect("plastic").rebase = None;
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene, "no re-basing stays none");

        let world = back.build(&BuildOptions::default()).expect("valid");
        let frame = world.frame();
        let wire = frame_to_proto("s", &frame);
        assert_eq!(
            wire.solids,
            vec![v1::SolidRange {
                system: 0,
                first: 0,
                count: frame.particle_count as u64,
            }]
        );
    }

    /// A solid message with only the required fields set builds the same
    /// solid as the TOML with only those keys: both front doors share
    /// the defaults.
    #[test]
    fn unset_solid_fields_take_the_scene_file_defaults() {
        let toml = r#"
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 1.0]
            [time]
            dt = 0.01
            [[systems]]
            kind = "solid"
            shape = { type = "sphere", radius = 0.2 }
            position = [0.5, 0.5, 0.5]
            spacing = 0.05
            young = 1.0e5
            surface = {}
        "#;
        let scene = Scene::from_toml_str(toml).expect("valid");
        let mut spec = scene_to_proto(&scene);
        spec.systems[0].kind = Some(v1::system_spec::Kind::Solid(v1::SolidSpec {
            shape: Some(v1::Shape {
                kind: Some(v1::shape::Kind::Sphere(v1::SphereShape { radius: 0.2 })),
            }),
            position: Some(to_vec3([0.5; 3])),
            spacing: 0.05,
            young: 1.0e5,
            surface: Some(v1::SolidSurfaceSpec::default()),
            ..Default::default()
        }));
        assert_eq!(scene_from_proto(spec.clone()).expect("valid"), scene);

        let mut no_method = spec.clone();
        let v1::SystemSpec {
            kind: Some(v1::system_spec::Kind::Solid(solid)),
        } = &mut spec.systems[0]
        else {
            panic!("a solid")
        };
        solid.order = Some(v1::MlsOrder::Unspecified as i32);
        let err = scene_from_proto(spec).expect_err("no order");
        assert!(err.to_string().starts_with("systems[0].order:"), "{err}");

        let v1::SystemSpec {
            kind: Some(v1::system_spec::Kind::Solid(solid)),
        } = &mut no_method.systems[0]
        else {
            panic!("a solid")
        };
        solid.surface = Some(v1::SolidSurfaceSpec {
            method: Some(v1::EmbeddingMethod::Unspecified as i32),
            subdivisions: None,
        });
        let err = scene_from_proto(no_method).expect_err("no method");
        assert!(
            err.to_string().starts_with("systems[0].surface.method:"),
            "{err}"
        );
    }

    #[test]
    fn missing_messages_name_their_field() {
        let mut spec = scene_to_proto(&dam_break());
        spec.time = None;
        assert!(
            scene_from_proto(spec)
                .expect_err("no time")
                .to_string()
                .starts_with("time:")
        );

        let mut spec = scene_to_proto(&dam_break());
        spec.systems[0].kind = None;
        let err = scene_from_proto(spec).expect_err("no kind");
        assert!(err.to_string().starts_with("systems[0].kind:"), "{err}");

        let mut spec = scene_to_proto(&dam_break());
        spec.output.as_mut().expect("output").fields.push(99);
        let err = scene_from_proto(spec).expect_err("bad field");
        assert!(err.to_string().starts_with("output.fields[3]:"), "{err}");
    }

    /// A surface request crosses with its default cell made explicit, and
    /// a frame's mesh goes out as packed f32 vertices and u32 indices.
    #[test]
    fn surfaces_cross_the_protocol() {
        let mut scene = dam_break();
        scene.output.surface = Some(SurfaceSpec {
            cell: None,
            iso: 0.4,
        });
        let spec = scene_to_proto(&scene);
        let wire = spec
            .output
            .as_ref()
            .and_then(|o| o.surface)
            .expect("surface");
        assert_eq!((wire.cell, wire.iso), (Some(0.01), Some(0.4)));
        let back = scene_from_proto(spec).expect("round trip");
        assert_eq!(
            back.output.surface,
            Some(SurfaceSpec {
                cell: Some(0.01),
                iso: 0.4
            })
        );

        let frame = back.build(&BuildOptions::default()).expect("world").frame();
        let mesh = frame.surface.as_ref().expect("a surface");
        let wire = frame_to_proto("s", &frame).surface.expect("on the wire");
        assert_eq!(wire.vertices.len(), 12 * mesh.vertices.len());
        assert!(
            wire.normals.is_empty(),
            "the fluid's surface has no normals"
        );
        assert_eq!(wire.triangles.len(), 12 * mesh.triangles.len());
        let last = mesh.vertices.len() - 1;
        let z = f32::from_le_bytes(
            wire.vertices[12 * last + 8..12 * last + 12]
                .try_into()
                .expect("4"),
        );
        assert_eq!(z, mesh.vertices[last].z as f32);
        let t = u32::from_le_bytes(wire.triangles[4..8].try_into().expect("4 bytes"));
        assert_eq!(t, mesh.triangles[0][1]);
    }
}
