//! The two front doors of a scene: TOML text (`CreateSession.scene_toml`,
//! `meshless run`) and the protocol's `SceneSpec`, each followed by the
//! admission check a server runs before it allocates anything.

use crate::echo::assert_quotes_briefly;
use meshless_engine::scene::MeshFiles;
use meshless_engine::{BuildOptions, Scene};
use meshless_proto::v1;
use meshless_wire::scene::{scene_from_proto, scene_to_proto};
use prost::Message;

/// The limits of a server with no mesh directory, scaled down: a scene
/// the check passes may be estimated at most this big, and an input can
/// never make the check itself allocate much (the server's defaults
/// admit millions of particles; the paths are the same).
fn options() -> BuildOptions {
    BuildOptions {
        max_particles: 20_000,
        mesh_files: MeshFiles::None,
        max_mesh_bytes: 64 << 10,
        ..BuildOptions::default()
    }
}

/// Scene TOML: the reader, then [`Scene::check`] under a server's policy
/// ([`MeshFiles::None`], small limits). Checks that errors quote briefly,
/// and that a scene the check passes has a finite, positive memory
/// estimate (the server reserves it against its budget) and survives the
/// trip to a `SceneSpec` and back, and to TOML and back, unchanged and
/// still valid (see the private `admitted`).
pub fn scene_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Scene::from_toml_str(text) {
        Ok(scene) => admitted(data, scene),
        Err(e) => assert_quotes_briefly(data, &e.to_string()),
    }
}

/// `SceneSpec` bytes: the protocol decoder, the conversion to an engine
/// scene ([`scene_from_proto`]) and the check, with the properties of
/// [`scene_toml`].
pub fn scene_spec(data: &[u8]) {
    let Ok(spec) = v1::SceneSpec::decode(data) else {
        return;
    };
    match scene_from_proto(spec) {
        Ok(scene) => admitted(data, scene),
        Err(e) => assert_quotes_briefly(data, &e.to_string()),
    }
}

/// Most midpoint subdivisions of an embedded surface the targets check.
/// A finer surface takes the same path with 4 times the vertices per
/// subdivision (up to 20 x 4^7 triangles), and under the fuzzer's
/// coverage instrumentation the MLS work at its vertices took most of
/// the scene targets' time (a second for the finest): left out, they run
/// about ten times as many inputs. Beyond 7 the check refuses the surface
/// before any work, and those inputs are checked.
const MAX_CHECKED_SUBDIVISIONS: u32 = 2;

/// Whether a solid of `scene` embeds a surface of 3 to 7 subdivisions,
/// or the scene holds a modal solid: admitting one builds its octree,
/// assembles it and finds its modes (up to `MAX_NODES` nodes, seconds
/// to minutes), which would starve the fuzzer of inputs. Their parsing
/// is fuzzed all the same; their admission is tested in
/// `engine/src/world/tests.rs`, their protocol round trip in
/// `wire/src/modal.rs`.
fn fine_surface(scene: &Scene) -> bool {
    scene.systems.iter().any(|system| {
        system.as_modal_solid().is_some()
            || system
                .as_solid()
                .and_then(|solid| solid.surface.as_ref())
                .is_some_and(|surface| {
                    (MAX_CHECKED_SUBDIVISIONS + 1..=7).contains(&surface.subdivisions)
                })
    })
}

/// Checks `scene` (read from `input`) as a server admits it. If the check
/// refuses it, the error quotes briefly; if it passes, the estimate is
/// finite and positive, and the scene converts to a `SceneSpec` that
/// converts back to the same scene (compared as `SceneSpec`s, where every
/// default is explicit), that scene passes the check too, and so does
/// the scene's TOML read back.
///
/// # Panics
/// When a property fails.
pub(crate) fn admitted(input: &[u8], scene: Scene) {
    if fine_surface(&scene) {
        return;
    }
    let checked = match scene.clone().check(&options()) {
        Ok(checked) => checked,
        Err(e) => return assert_quotes_briefly(input, &e.to_string()),
    };
    let bytes = checked.footprint().bytes;
    assert!(
        bytes.is_finite() && bytes > 0.0,
        "the memory estimate of an admitted scene is {bytes} bytes"
    );
    let spec = scene_to_proto(&scene);
    let back = scene_from_proto(spec.clone())
        .unwrap_or_else(|e| panic!("an admitted scene's SceneSpec does not convert back: {e}"));
    assert_eq!(scene_to_proto(&back), spec, "SceneSpec round trip");
    if let Err(e) = back.check(&options()) {
        panic!("an admitted scene is refused after the SceneSpec round trip: {e}");
    }
    let text = scene.to_toml_string();
    let again = Scene::from_toml_str(&text)
        .unwrap_or_else(|e| panic!("an admitted scene's TOML does not read back: {e}\n{text}"));
    assert_eq!(scene_to_proto(&again), spec, "TOML round trip of\n{text}");
}
