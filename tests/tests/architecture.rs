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
    sources(&format!("engine/src/{dir}"))
}

/// Every `.rs` file under `FOLDER` (from the workspace root), with its
/// text.
fn sources(folder: &str) -> Vec<(std::path::PathBuf, String)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(folder);
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
    const BELOW_SYSTEMS: &[&str] = &[
        "crate::world",
        "crate::scene",
        "crate::fluid",
        "crate::solid",
        "crate::efg",
        "crate::modal",
        "crate::design",
    ];
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
        // Thin shells sit on geometry, approximation and linear algebra
        // alone, as geometry sits below every system.
        ("shell", BELOW_SYSTEMS),
        ("geometry", BELOW_SYSTEMS),
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

/// The modules a crate root (`lib.rs`, `main.rs`) declares: `mod x;`,
/// `pub mod x;`, `pub(crate) mod x;`, read from its text.
fn declared_modules(root: &str) -> BTreeSet<String> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(root);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let modules: BTreeSet<String> = text
        .lines()
        .map(str::trim)
        .filter_map(|line| {
            let line = line
                .strip_prefix("pub(crate) ")
                .or_else(|| line.strip_prefix("pub "))
                .unwrap_or(line);
            line.strip_prefix("mod ")?.strip_suffix(';')
        })
        .map(|name| name.trim().to_string())
        .collect();
    assert!(!modules.is_empty(), "{root} declares no module");
    modules
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

/// The crate roots whose modules the rule below reads, with their source
/// folders.
const CRATE_ROOTS: &[(&str, &str)] = &[
    ("engine/src/lib.rs", "engine/src"),
    ("wire/src/lib.rs", "wire/src"),
    ("server/src/lib.rs", "server/src"),
    ("cli/src/main.rs", "cli/src"),
];

/// A crate's modules import from its other modules (`crate::world::World`),
/// never an item of the crate root (`crate::World`, a re-export, or a
/// constant `lib.rs` defines): the root's items are the crate's public
/// face, and a module that reaches up to the root for them hides the real
/// edge (and closes a loop through `lib.rs`, which declares the module)
/// from anyone reading its imports. Comment lines (doc links) are not
/// imports and are skipped; so is `$crate` in macros.
#[test]
fn modules_do_not_import_items_of_their_crate_root() {
    let mut offenders = Vec::new();
    for (root, folder) in CRATE_ROOTS {
        let modules = declared_modules(root);
        let root_file = std::path::Path::new(root).file_name().expect("a file name");
        let top = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(folder);
        for (path, text) in sources(folder) {
            if path.parent() == Some(top.as_path()) && path.file_name() == Some(root_file) {
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
                    .is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':' || c == '$');
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
                        if !modules.contains(head) && head != "self" {
                            offenders.push(format!("{}: crate::{head}", path.display()));
                        }
                    }
                }
                rest = after;
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "modules import items of their crate root; import from the item's home module \
         instead:\n{}",
        offenders.join("\n")
    );
}
