//! The engine is a plain library: it must never depend, even indirectly,
//! on the async runtime, gRPC or zenoh (DESIGN.md, "Workspace").

use std::collections::{HashMap, HashSet};

const FORBIDDEN: &[&str] = &["tokio", "tonic", "zenoh", "prost", "hyper", "mio"];

#[test]
fn the_engine_depends_on_no_networking_crate() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.toml");
    let output = std::process::Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--offline",
            "--manifest-path",
            manifest,
        ])
        .output()
        .expect("cargo metadata runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metadata: serde_json::Value = serde_json::from_slice(&output.stdout).expect("json");

    let names: HashMap<&str, &str> = metadata["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .map(|p| {
            (
                p["id"].as_str().expect("id"),
                p["name"].as_str().expect("name"),
            )
        })
        .collect();
    let nodes: HashMap<&str, Vec<&str>> = metadata["resolve"]["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .map(|n| {
            let deps = n["deps"]
                .as_array()
                .expect("deps")
                .iter()
                // Normal (non-dev, non-build) dependencies only.
                .filter(|d| {
                    d["dep_kinds"]
                        .as_array()
                        .is_some_and(|k| k.iter().any(|k| k["kind"].is_null()))
                })
                .map(|d| d["pkg"].as_str().expect("pkg"))
                .collect();
            (n["id"].as_str().expect("id"), deps)
        })
        .collect();
    let engine = names
        .iter()
        .find(|(_, name)| **name == "meshless-engine")
        .map(|(id, _)| *id)
        .expect("the engine is a workspace member");

    let mut seen = HashSet::new();
    let mut stack = vec![engine];
    while let Some(id) = stack.pop() {
        if !seen.insert(id) {
            continue;
        }
        let name = names[id];
        assert!(
            !FORBIDDEN.contains(&name),
            "meshless-engine depends on {name}; keep networking out of the engine"
        );
        stack.extend(nodes.get(id).into_iter().flatten());
    }
    // The walk really covered the engine's dependencies.
    assert!(seen.iter().any(|id| names[id] == "nalgebra"));
    assert!(seen.iter().any(|id| names[id] == "rayon"));
}
