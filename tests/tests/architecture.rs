//! The crate rules (DESIGN.md, "Workspace"), checked on the real
//! dependency graph with `cargo tree`. The engine is a plain library: it
//! must never depend, even indirectly, on the async runtime, gRPC or
//! zenoh. The protocol and the engine meet only in `meshless-wire`
//! (`wire -> {engine, proto}`, `server -> {engine, wire, proto}`); the
//! client library depends on the protocol alone; the command line
//! (`cli -> {client, wire, validation}`) links the engine and a server
//! only under its `embedded` feature; validation sits on the engine alone.
//! Inside the engine, the sources show that imports point downward
//! (LAYOUT.md: `frame <- scene <- world`, systems import neither).

use std::collections::BTreeSet;

const FORBIDDEN: &[&str] = &["tokio", "tonic", "zenoh", "prost", "hyper", "mio"];

/// The workspace's own crates.
const WORKSPACE: &[&str] = &[
    "meshless-proto",
    "meshless-engine",
    "meshless-wire",
    "meshless-validation",
    "meshless-server",
    "meshless-client",
    "meshless-cli",
    "meshless-tests",
];

/// The package names of `package`'s normal (non-dev, non-build)
/// dependency tree on this platform, one per line of `cargo tree`, the
/// package itself first; `args` adds flags (`--depth 1`,
/// `--no-default-features`).
fn tree(package: &str, args: &[&str]) -> Vec<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.toml");
    let output = std::process::Command::new(cargo)
        .args([
            "tree",
            "--offline",
            "--manifest-path",
            manifest,
            "-p",
            package,
        ])
        .args(["-e", "normal", "--prefix", "none", "--format", "{p}"])
        .args(args)
        .output()
        .expect("cargo tree runs");
    assert!(
        output.status.success(),
        "cargo tree -p {package} {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let names: Vec<String> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_owned)
        .collect();
    assert_eq!(
        names.first().map(String::as_str),
        Some(package),
        "the walk starts at {package}"
    );
    names
}

/// The workspace crates in a tree, the package itself left out.
fn workspace_crates(names: &[String]) -> BTreeSet<&str> {
    names[1..]
        .iter()
        .map(String::as_str)
        .filter(|name| WORKSPACE.contains(name))
        .collect()
}

/// The workspace crates `package` depends on directly.
fn direct(package: &str, args: &[&str]) -> BTreeSet<String> {
    let names = tree(package, &[&["--depth", "1"], args].concat());
    workspace_crates(&names)
        .into_iter()
        .map(str::to_owned)
        .collect()
}

fn set(names: &[&str]) -> BTreeSet<String> {
    names.iter().map(|&n| n.to_owned()).collect()
}

#[test]
fn the_engine_depends_on_no_networking_crate() {
    let names = tree("meshless-engine", &[]);
    for name in &names {
        assert!(
            !FORBIDDEN.contains(&name.as_str()),
            "meshless-engine depends on {name}; keep networking out of the engine"
        );
    }
    // The walk really covered the engine's dependencies.
    assert!(
        names.iter().any(|n| n == "nalgebra") && names.iter().any(|n| n == "rayon"),
        "{names:?}"
    );
    assert!(
        workspace_crates(&names).is_empty(),
        "the engine depends on {:?}; it knows neither the protocol nor the wire",
        workspace_crates(&names)
    );
}

/// Proto and engine types meet in the wire crate, which the server uses.
#[test]
fn the_protocol_meets_the_engine_only_in_the_wire_crate() {
    assert_eq!(
        direct("meshless-wire", &[]),
        set(&["meshless-engine", "meshless-proto"])
    );
    assert_eq!(
        direct("meshless-server", &[]),
        set(&["meshless-engine", "meshless-proto", "meshless-wire"])
    );
}

/// A program that only talks to servers links neither engine, server nor
/// wire.
#[test]
fn the_client_library_depends_on_the_protocol_alone() {
    let names = tree("meshless-client", &[]);
    assert_eq!(
        workspace_crates(&names),
        BTreeSet::from(["meshless-proto"]),
        "meshless-client must stay thin"
    );
}

/// `meshless` with its default `embedded` feature runs scenes and servers
/// in-process; without it, it is a client and nothing more.
#[test]
fn the_command_line_links_engine_and_server_only_when_embedded() {
    assert_eq!(
        direct("meshless-cli", &[]),
        set(&[
            "meshless-client",
            "meshless-engine",
            "meshless-server",
            "meshless-validation",
            "meshless-wire",
        ])
    );
    let thin = tree("meshless-cli", &["--no-default-features"]);
    assert_eq!(
        workspace_crates(&thin),
        BTreeSet::from(["meshless-client", "meshless-proto"]),
        "meshless-cli --no-default-features links only the client library"
    );
}

/// The experiments need the engine and nothing networked.
#[test]
fn validation_sits_on_the_engine_alone() {
    let names = tree("meshless-validation", &[]);
    assert_eq!(
        workspace_crates(&names),
        BTreeSet::from(["meshless-engine"])
    );
    for name in &names {
        assert!(
            !FORBIDDEN.contains(&name.as_str()),
            "meshless-validation depends on {name}; the experiments need no networking"
        );
    }
}

/// Every `.rs` file under `engine/src/DIR`, with its text.
fn engine_sources(dir: &str) -> Vec<(std::path::PathBuf, String)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../engine/src")
        .join(dir);
    let mut pending = vec![root.clone()];
    let mut files = Vec::new();
    while let Some(dir) = pending.pop() {
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&path)
                    .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
                files.push((path, text));
            }
        }
    }
    assert!(!files.is_empty(), "no sources under {}", root.display());
    files
}

/// Inside the engine, `frame <- scene <- world`: the spec never reaches
/// for the world it is built into, and the systems (fluid, rigid bodies,
/// solids) never import the world or the spec, so that a new system or a
/// new spec field cannot close an import loop.
#[test]
fn engine_modules_import_downward_only() {
    let rules: &[(&str, &[&str])] = &[
        ("scene", &["crate::world"]),
        ("fluid", &["crate::world", "crate::scene"]),
        ("rigid", &["crate::world", "crate::scene"]),
        ("solid", &["crate::world", "crate::scene"]),
        ("linalg", &["crate::world", "crate::scene"]),
        (
            "efg",
            &[
                "crate::world",
                "crate::scene",
                "crate::fluid",
                "crate::design",
            ],
        ),
        (
            "modal",
            &[
                "crate::world",
                "crate::scene",
                "crate::fluid",
                "crate::solid",
                "crate::efg",
                "crate::design",
            ],
        ),
        (
            "geometry",
            &[
                "crate::world",
                "crate::scene",
                "crate::fluid",
                "crate::solid",
                "crate::efg",
                "crate::modal",
                "crate::design",
            ],
        ),
    ];
    for (dir, forbidden) in rules {
        for (path, text) in engine_sources(dir) {
            for module in *forbidden {
                assert!(
                    !text.contains(module),
                    "{} names {module}; engine/src/{dir} must not import it (LAYOUT.md)",
                    path.display()
                );
            }
        }
    }
}

/// The names `engine/src/lib.rs` re-exports at the crate root (`pub use
/// home::{A, B};`), read from its text.
fn crate_root_reexports() -> BTreeSet<String> {
    let lib = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../engine/src/lib.rs");
    let text = std::fs::read_to_string(&lib)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", lib.display()));
    let mut names = BTreeSet::new();
    let mut rest = text.as_str();
    while let Some(at) = rest.find("pub use ") {
        let tail = &rest[at + "pub use ".len()..];
        let end = tail.find(';').expect("a `pub use` ends with `;`");
        let item = &tail[..end];
        let list = match item.find('{') {
            Some(open) => &item[open + 1..item.rfind('}').expect("a closed group")],
            None => item.rsplit("::").next().expect("a path"),
        };
        for name in list.split(',') {
            let name = name.rsplit(" as ").next().expect("a name").trim();
            if !name.is_empty() {
                names.insert(name.to_string());
            }
        }
        rest = &tail[end + 1..];
    }
    assert!(
        names.contains("World"),
        "lib.rs re-exports World: {names:?}"
    );
    names
}

/// The first path segment of each entry of a `crate::{...}` group that
/// starts at `group` (just after the `{`), nested groups skipped.
fn group_heads(group: &str) -> Vec<&str> {
    let mut heads = Vec::new();
    let (mut depth, mut start) = (0usize, 0usize);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                heads.push(&group[start..i]);
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                heads.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    heads
        .into_iter()
        .map(|entry| entry.trim().split("::").next().unwrap_or("").trim())
        .map(|head| head.split(" as ").next().unwrap_or("").trim())
        .filter(|head| !head.is_empty())
        .collect()
}

/// Engine modules import a type from its home module (`crate::world::World`),
/// never through the crate-root re-export (`crate::World`): the re-exports
/// are the public face of the crate, and a module that reaches up to the
/// root for them hides the real edge (and can close a loop through
/// `lib.rs`) from anyone reading its imports. Comment lines (doc links)
/// are not imports and are skipped.
#[test]
fn engine_modules_do_not_import_crate_root_reexports() {
    let names = crate_root_reexports();
    let mut offenders = Vec::new();
    for (path, text) in engine_sources("") {
        if path.ends_with("lib.rs") && path.parent().is_some_and(|p| p.ends_with("src")) {
            continue;
        }
        let code: String = text
            .lines()
            .filter(|line| !line.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let mut rest = code.as_str();
        while let Some(at) = rest.find("crate::") {
            let after = &rest[at + "crate::".len()..];
            let preceded = rest[..at]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':');
            if !preceded {
                let heads = if let Some(group) = after.strip_prefix('{') {
                    group_heads(group)
                } else {
                    let end = after
                        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                        .unwrap_or(after.len());
                    vec![&after[..end]]
                };
                for head in heads {
                    if names.contains(head) {
                        offenders.push(format!("{}: crate::{head}", path.display()));
                    }
                }
            }
            rest = after;
        }
    }
    assert!(
        offenders.is_empty(),
        "engine modules import crate-root re-exports; import from the home module instead:\n{}",
        offenders.join("\n")
    );
}
