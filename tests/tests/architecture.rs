//! The engine is a plain library: it must never depend, even indirectly,
//! on the async runtime, gRPC or zenoh (DESIGN.md, "Workspace").

const FORBIDDEN: &[&str] = &["tokio", "tonic", "zenoh", "prost", "hyper", "mio"];

#[test]
fn the_engine_depends_on_no_networking_crate() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.toml");
    // The engine's normal (non-dev, non-build) dependency tree on this
    // platform, one package per line.
    let output = std::process::Command::new(cargo)
        .args([
            "tree",
            "--offline",
            "--manifest-path",
            manifest,
            "-p",
            "meshless-engine",
        ])
        .args(["-e", "normal", "--prefix", "none", "--format", "{p}"])
        .output()
        .expect("cargo tree runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let tree = String::from_utf8_lossy(&output.stdout);
    let names: Vec<&str> = tree
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    for name in &names {
        assert!(
            !FORBIDDEN.contains(name),
            "meshless-engine depends on {name}; keep networking out of the engine"
        );
    }
    // The walk really covered the engine's dependencies.
    assert_eq!(names.first(), Some(&"meshless-engine"));
    assert!(
        names.contains(&"nalgebra") && names.contains(&"rayon"),
        "{names:?}"
    );
}
