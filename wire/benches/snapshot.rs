//! What a snapshot of a large fluid costs: its size, and the time of each
//! stage a `Snapshot` and a `Restore` go through (the state captured
//! between two steps, converted to the protocol, framed with its
//! checksum; then checked and decoded, converted back, a world built from
//! the scene and moved to the state). A DFSPH dam-break column of about
//! 150,000 particles, stepped once so that its warm start is real.
//!
//! `cargo bench -p meshless-wire --bench snapshot`; with
//! `MESHLESS_BENCH_SMOKE=1`, or under `cargo test` (which builds and runs
//! it with the tests), the same stages on about 1,000 particles.

#[path = "../../engine/benches/common/smoke.rs"]
mod smoke;

use meshless_engine::{BuildOptions, Scene, World};
use meshless_proto::snapshot as blob;
use meshless_proto::v1;
use meshless_wire::scene::{scene_from_proto, scene_to_proto};
use meshless_wire::snapshot::{world_state_from_proto, world_state_to_proto};
use std::time::Instant;

/// Times `work`, best of `runs`, printing the stage; returns its result.
fn stage<T>(name: &str, runs: usize, mut work: impl FnMut() -> T) -> T {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..runs {
        let start = Instant::now();
        let value = work();
        best = best.min(start.elapsed().as_secs_f64());
        out = Some(value);
    }
    println!("| {name:<40} | {:>9.1} |", best * 1e3);
    out.expect("at least one run")
}

/// `normal` under `cargo bench` (which passes `--bench`) unless in smoke
/// mode, else `small`.
fn pick<T>(normal: T, small: T) -> T {
    let benched = std::env::args().any(|a| a == "--bench");
    if benched {
        smoke::pick(normal, small)
    } else {
        small
    }
}

fn main() {
    let spacing = pick(0.01, 0.05);
    let side = pick(0.53, 0.5);
    let runs = pick(3, 1);
    let scene = Scene::from_toml_str(&format!(
        r#"
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.6, 1.0, {side}]
        [time]
        dt = 0.002
        [[systems]]
        kind = "fluid"
        solver = "dfsph"
        spacing = {spacing}
        [[systems.blocks]]
        region = {{ min = [0.0, 0.0, 0.0], max = [{side}, {side}, {side}] }}
        "#
    ))
    .expect("the column parses");
    let options = BuildOptions::default();
    let mut world = scene.build(&options).expect("the column builds");
    world.step().expect("a stable step");
    println!(
        "snapshot of a DFSPH column of {} particles, best of {runs} (ms):\n",
        world.particle_count()
    );
    println!("| stage                                    |        ms |");
    println!("|---|---:|");
    let state = stage("capture the state (between two steps)", runs, || {
        world.state()
    });
    let payload = stage("convert to the protocol", runs, || v1::SnapshotPayload {
        scene: Some(scene_to_proto(&scene)),
        world: Some(world_state_to_proto(&state)),
        ..Default::default()
    });
    let data = stage("encode and checksum (SHA-256)", runs, || {
        blob::encode(&payload)
    });
    let decoded = stage("check and decode", runs, || {
        blob::decode(&data, usize::MAX).expect("its own blob")
    });
    let (scene_back, state_back) = stage("convert from the protocol", runs, || {
        let decoded = decoded.clone();
        (
            scene_from_proto(decoded.scene.expect("a scene")).expect("converts"),
            world_state_from_proto(decoded.world.expect("a world")).expect("converts"),
        )
    });
    let fresh: World = stage("build the scene's world", runs, || {
        scene_back.build(&options).expect("builds")
    });
    let restored = stage("restore the state into it", runs, || {
        fresh.clone().restored(&state_back).expect("fits")
    });
    assert_eq!(restored.clock(), world.clock());
    let mb = data.len() as f64 / (1 << 20) as f64;
    println!(
        "\n{} bytes ({mb:.1} MiB), {:.1} bytes per particle",
        data.len(),
        data.len() as f64 / world.particle_count() as f64
    );
}
