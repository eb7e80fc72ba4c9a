//! The snapshot decoder: what `Restore` and a server reading its
//! checkpoints do with bytes from a client or a disk. The fuzzer's bytes
//! are read twice: as a blob (the framing: header, build, length,
//! checksum), and as the payload inside one, framed here with a valid
//! checksum so that the fuzzer reaches past it, through the conversions
//! into a world built from the payload's scene and moved to its state,
//! and one step of it.

use crate::echo::assert_quotes_briefly;
use meshless_engine::{BuildOptions, Scene, World};
use meshless_proto::snapshot as blob;
use meshless_proto::v1;
use meshless_wire::scene::scene_from_proto;
use meshless_wire::snapshot::{world_state_from_proto, world_state_to_proto};
use prost::Message;

/// Largest blob the target reads, as a server's `--max-snapshot-mb`.
const LIMIT: usize = 1 << 20;

/// Particles a fuzzed scene may build: enough for every kind of system,
/// few enough to step in a millisecond.
const MAX_PARTICLES: u64 = 2_000;

/// Snapshot bytes through the decoder. A blob never panics the framing,
/// and its errors quote briefly. A payload framed with a valid checksum
/// decodes to itself; its scene and state, when they convert and fit,
/// restore into a world whose own state restores again unchanged (bit
/// for bit, through the protocol), and the world takes a step without
/// panicking.
///
/// # Panics
/// When a property fails.
pub fn snapshot(data: &[u8]) {
    if let Err(e) = blob::decode(data, LIMIT) {
        assert_quotes_briefly(data, &e.to_string());
    }
    let Ok(payload) = v1::SnapshotPayload::decode(data) else {
        return;
    };
    let framed = blob::encode(&payload);
    let decoded = blob::decode(&framed, usize::MAX)
        .unwrap_or_else(|e| panic!("a framed payload does not decode: {e}"));
    assert_eq!(
        decoded.encode_to_vec(),
        payload.encode_to_vec(),
        "decode(encode(payload)) differs"
    );
    let (Some(scene), Some(world)) = (payload.scene, payload.world) else {
        return;
    };
    let scene: Scene = match scene_from_proto(scene) {
        Ok(scene) => scene,
        Err(e) => return assert_quotes_briefly(data, &e.to_string()),
    };
    let state = match world_state_from_proto(world.clone()) {
        Ok(state) => state,
        Err(e) => return assert_quotes_briefly(data, &e.to_string()),
    };
    let options = BuildOptions {
        max_particles: MAX_PARTICLES,
        ..BuildOptions::default()
    };
    let Ok(checked) = scene.check(&options) else {
        return;
    };
    let built: World = checked.build();
    let fresh = built.clone();
    let mut restored = match built.restored(&state) {
        Ok(world) => world,
        Err(e) => return assert_quotes_briefly(data, &e.to_string()),
    };
    // What a restored world gives back is a state it takes again, to the
    // bit (the input may be less canonical: removals unsorted, flags a
    // system ignores).
    let state = restored.state();
    let again = fresh
        .restored(&state)
        .unwrap_or_else(|e| panic!("a restored world's own state is refused: {e}"));
    assert_eq!(
        world_state_to_proto(&again.state()).encode_to_vec(),
        world_state_to_proto(&state).encode_to_vec(),
        "restoring a restored world's state changes it"
    );
    // A hostile state may be unstable: an error, never a panic.
    let _ = restored.step();
}
