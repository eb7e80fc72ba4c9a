//! The documentation points only at files that exist, the README stays
//! short, it links every page of `docs/`, and every command it cites is
//! smoke-run by `scripts/smoke-docs` (the rules are above that test).
//!
//! Read: `README.md`, `CONTRIBUTING.md` and every `docs/*.md`. A
//! *reference* is either a word of an inline code span (the span split at
//! whitespace, so the paths inside a command count too) or the target of a
//! Markdown link or image (without its `#anchor`). A reference names a
//! repository file or folder when it is made only of ASCII letters,
//! digits and `_ . - /`, has no empty path component, and contains a `/`
//! or ends in `.rs .toml .md .proto .py .png .csv .sh`. Code words are
//! relative to the repository root, link targets to the linking file.
//!
//! Skipped, and nothing else:
//! - fenced code blocks (commands and program output);
//! - URLs, globs and `{...}` placeholders (their `:`, `*`, `{` are not path
//!   characters), flags and absolute paths (a leading `-` or `/`);
//! - outputs: paths under `out/` or `target/`;
//! - placeholders in capitals: a component whose name before its first
//!   `.` is capitals, digits and `_` (`NAME.rs`, `PATH`), unless it ends in
//!   `.md` (`README.md` is a real file).

use std::path::{Path, PathBuf};

/// Extensions of the files the documents cite.
const EXTENSIONS: &[&str] = &["rs", "toml", "md", "proto", "py", "png", "csv", "sh"];

/// The README's length limit: the pitch, the quick start and an index;
/// everything else lives in `docs/`.
const README_LINES: usize = 200;

/// Where a reference was written, which decides what it is relative to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Origin {
    /// A word of an inline code span: relative to the repository root.
    Code,
    /// A link or image target: relative to the file that holds it.
    Link,
}

/// The repository root (this crate lives in `tests/`).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// The text outside fenced code blocks.
fn prose(text: &str) -> String {
    let mut fenced = false;
    let mut out = String::new();
    for line in text.lines() {
        let start = line.trim_start();
        if start.starts_with("```") || start.starts_with("~~~") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// Link and image targets in `text` (no code spans in it), without their
/// `#anchor` or title; pure anchors are left out.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let end = rest.find(')').unwrap_or(rest.len());
        let target = rest[..end].split_whitespace().next().unwrap_or("");
        let target = target.split('#').next().unwrap_or("");
        if !target.is_empty() {
            targets.push(target.to_owned());
        }
        rest = &rest[end..];
    }
    targets
}

/// Every reference in a Markdown text, in order: code words and link
/// targets, fenced blocks left out.
fn references(text: &str) -> Vec<(Origin, String)> {
    let mut found = Vec::new();
    // Splitting at backticks alternates prose and code spans; spans may
    // run over a line break.
    for (k, part) in prose(text).split('`').enumerate() {
        if k % 2 == 1 {
            found.extend(
                part.split_whitespace()
                    .map(|word| (Origin::Code, word.to_owned())),
            );
        } else {
            found.extend(
                link_targets(part)
                    .into_iter()
                    .map(|target| (Origin::Link, target)),
            );
        }
    }
    found
}

/// Whether a component is a placeholder written in capitals.
fn is_placeholder(component: &str) -> bool {
    if component.ends_with(".md") {
        return false;
    }
    let stem = component.split('.').next().unwrap_or("");
    stem.chars().any(|c| c.is_ascii_uppercase())
        && stem
            .chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

/// Whether a reference names a repository file or folder (the rules of
/// the module comment).
fn is_repository_path(reference: &str) -> bool {
    let path_chars = reference
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-' | '/'));
    if !path_chars || reference.starts_with(['-', '/']) {
        return false;
    }
    let components: Vec<&str> = reference.trim_end_matches('/').split('/').collect();
    if components.iter().any(|c| c.is_empty()) {
        return false;
    }
    let extension = reference.rsplit_once('.').map(|(_, ext)| ext);
    let cited = reference.contains('/') || extension.is_some_and(|ext| EXTENSIONS.contains(&ext));
    let output = reference.starts_with("out/") || reference.starts_with("target/");
    cited && !output && !components.iter().any(|c| is_placeholder(c))
}

/// The repository paths a document cites, each resolved from the
/// repository root (`dir`: the document's folder, for its links).
fn cited_paths(dir: &Path, text: &str) -> Vec<PathBuf> {
    references(text)
        .into_iter()
        .filter(|(_, reference)| is_repository_path(reference))
        .map(|(origin, reference)| match origin {
            Origin::Code => PathBuf::from(reference),
            Origin::Link => dir.join(reference),
        })
        .collect()
}

/// The cited paths of a document that do not exist under `root`.
fn missing(root: &Path, dir: &Path, text: &str) -> Vec<String> {
    cited_paths(dir, text)
        .into_iter()
        .filter(|path| !root.join(path).exists())
        .map(|path| path.display().to_string())
        .collect()
}

/// `README.md`, `CONTRIBUTING.md` and `docs/*.md`, relative to the root.
fn documents(root: &Path) -> Vec<PathBuf> {
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/ is readable")
        .map(|entry| entry.expect("a docs/ entry").path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "md"))
        .map(|path| {
            path.strip_prefix(root)
                .expect("docs/ is inside the root")
                .to_path_buf()
        })
        .collect();
    docs.sort();
    let mut all = vec![PathBuf::from("README.md"), PathBuf::from("CONTRIBUTING.md")];
    all.append(&mut docs);
    all
}

fn read(root: &Path, document: &Path) -> String {
    std::fs::read_to_string(root.join(document))
        .unwrap_or_else(|e| panic!("{}: {e}", document.display()))
}

#[test]
fn the_extractor_reads_code_words_and_links_and_skips_the_rest() {
    let text = "\
Run `meshless run scenes/dam_break.toml -o out/run` (see
[the scenes](docs/scenes.md#fluids), ![a figure](figures/a.png)
and [salva](https://salva.rs)).

```bash
scripts/in_a_fence.sh
```

A span over a line: `cargo test --test
golden` in `tests/tests/golden.rs`; `scenes/*.toml`,
`meshless/v1/sessions/{id}/frames`, `engine/src/fluid/pressure/NAME.rs`,
`README.md`, `Z = x / a`, `f a//a`, `--out`, `lib.rs` and `frame.step`.
";
    let cited: Vec<String> = cited_paths(Path::new("docs"), text)
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    assert_eq!(
        cited,
        [
            "scenes/dam_break.toml",
            "docs/docs/scenes.md",
            "docs/figures/a.png",
            "tests/tests/golden.rs",
            "README.md",
            "lib.rs",
        ],
        "code words are root-relative, links relative to the document"
    );
}

#[test]
fn a_missing_file_is_reported() {
    let text = "`Cargo.toml`, `engine/src/no_such_module.rs`, [x](docs/nowhere.md), \
                [readme](README.md) and `scripts/test`";
    assert_eq!(
        missing(&root(), Path::new(""), text),
        ["engine/src/no_such_module.rs", "docs/nowhere.md"]
    );
}

#[test]
fn every_path_the_documents_cite_exists() {
    let root = root();
    let mut problems = Vec::new();
    for document in documents(&root) {
        let dir = document.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut paths = missing(&root, &dir, &read(&root, &document));
        paths.sort();
        paths.dedup();
        for path in paths {
            problems.push(format!("{}: {path}", document.display()));
        }
    }
    assert!(
        problems.is_empty(),
        "documents cite paths that do not exist (fix the path, or see the \
         skip rules in tests/tests/docs.rs):\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_readme_is_at_most_200_lines() {
    let lines = read(&root(), Path::new("README.md")).lines().count();
    assert!(
        lines <= README_LINES,
        "README.md has {lines} lines, more than {README_LINES}: move detail to docs/"
    );
}

#[test]
fn the_readme_links_every_document() {
    let root = root();
    let readme = read(&root, Path::new("README.md"));
    let linked: Vec<PathBuf> = references(&readme)
        .into_iter()
        .filter(|(origin, _)| *origin == Origin::Link)
        .map(|(_, target)| PathBuf::from(target.trim_start_matches("./")))
        .collect();
    for document in documents(&root).iter().skip(1) {
        assert!(
            linked.contains(document),
            "README.md does not link {}; add it to its documentation index",
            document.display()
        );
    }
}

// ---------------------------------------------------------------------------
// Every command the documents cite is smoke-run by `scripts/smoke-docs`.
//
// A *command* is an inline code span (whitespace collapsed, so a span may
// run over a line break) or a line of a fenced block whose words, after any
// leading `NAME=value` assignments and before a `#` comment, start with one
// of: `cargo bench`, `cargo run`, `scripts/…`, `python scripts/…`,
// `meshless SUBCOMMAND` or `meshless-server` (also as
// `target/{release,debug}/…`). Its *key* is the program and subcommand,
// what `scripts/smoke-docs` names in a `# covers: KEY` line:
//
// - `cargo bench -p CRATE --bench NAME` (a placeholder NAME in capitals is
//   no command);
// - `cargo run -p meshless-cli -- SUB …` is the `meshless SUB` key, like
//   `meshless SUB …` itself; `session` keeps its action
//   (`meshless session create`);
// - `scripts/NAME`, with or without `python` in front;
// - `meshless-server`.
//
// `meshless` counts only before a real subcommand, so prose such as
// `meshless runs at 1.16x` is no command, and `meshless import` is Python
// (`from meshless import Client`), not a command either.
// ---------------------------------------------------------------------------

/// The script that smoke-runs every cited command, from the root.
const SMOKE_SCRIPT: &str = "scripts/smoke-docs";

/// What marks a command as covered in [`SMOKE_SCRIPT`].
const COVERS: &str = "# covers:";

/// The words that may follow `meshless` in a command (`import` is listed
/// to be recognised and skipped: it is Python).
const MESHLESS_SUBCOMMANDS: &[&str] = &[
    "run", "demo", "study", "optimise", "session", "watch", "server", "import", "health",
];

/// The actions of `meshless session`.
const SESSION_ACTIONS: &[&str] = &[
    "create", "list", "get", "step", "run", "pause", "resume", "reset", "delete", "simulate",
    "snapshot", "restore",
];

/// Inline code spans (whitespace collapsed) and fenced lines of a Markdown
/// text: where commands are written.
fn command_texts(text: &str) -> Vec<String> {
    let mut texts = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        let start = line.trim_start();
        if start.starts_with("```") || start.starts_with("~~~") {
            fenced = !fenced;
        } else if fenced {
            texts.push(start.trim_end().to_owned());
        }
    }
    for (k, part) in prose(text).split('`').enumerate() {
        if k % 2 == 1 {
            texts.push(part.split_whitespace().collect::<Vec<_>>().join(" "));
        }
    }
    texts
}

/// A command line split into words at whitespace outside double or single
/// quotes (`RUSTFLAGS="-C target-cpu=x86-64-v3"` is one word).
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut quote = None;
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (None, '"' | '\'') => quote = Some(c),
            (None, c) if c.is_whitespace() => {
                if !word.is_empty() {
                    words.push(std::mem::take(&mut word));
                }
            }
            (_, c) => word.push(c),
        }
    }
    if !word.is_empty() {
        words.push(word);
    }
    words
}

/// Whether a word is an environment assignment, `NAME=value`.
fn is_assignment(word: &str) -> bool {
    word.split_once('=').is_some_and(|(name, _)| {
        !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
    })
}

/// The value of `flag` in `words` (`-p X` or `-p=X`).
fn flag_value<'a>(words: &[&'a str], flag: &str) -> Option<&'a str> {
    words.iter().enumerate().find_map(|(i, word)| {
        if *word == flag {
            words.get(i + 1).copied()
        } else {
            word.strip_prefix(flag)?.strip_prefix('=')
        }
    })
}

/// The key of `meshless WORDS…`, if the first word is a subcommand.
fn meshless_key(words: &[&str]) -> Option<String> {
    let sub = *words.first()?;
    if !MESHLESS_SUBCOMMANDS.contains(&sub) || sub == "import" {
        return None;
    }
    match words.get(1) {
        Some(action) if sub == "session" && SESSION_ACTIONS.contains(action) => {
            Some(format!("meshless session {action}"))
        }
        _ => Some(format!("meshless {sub}")),
    }
}

/// The key of a command (the rules above), or `None` when the text is no
/// command.
fn command_key(text: &str) -> Option<String> {
    let words = shell_words(text);
    let words: Vec<&str> = words
        .iter()
        .map(String::as_str)
        .skip_while(|w| is_assignment(w))
        .take_while(|w| !w.starts_with('#'))
        .collect();
    let (&program, rest) = words.split_first()?;
    let program = ["target/release/", "target/debug/"]
        .iter()
        .find_map(|dir| program.strip_prefix(dir))
        .unwrap_or(program);
    let script = |path: &str| {
        ((path.starts_with("scripts/") || is_executable_in_deploy(path))
            && !path.ends_with('/')
            && !path.split('/').any(is_placeholder))
        .then(|| path.to_owned())
    };
    match program {
        "cargo" => match rest.first() {
            Some(&"bench") => {
                let mut key = String::from("cargo bench");
                if let Some(package) = flag_value(rest, "-p") {
                    key.push_str(&format!(" -p {package}"));
                }
                if let Some(bench) = flag_value(rest, "--bench") {
                    if is_placeholder(bench) {
                        return None;
                    }
                    key.push_str(&format!(" --bench {bench}"));
                }
                Some(key)
            }
            Some(&"run") => match flag_value(rest, "-p") {
                Some("meshless-cli") => {
                    let at = rest.iter().position(|w| *w == "--")?;
                    meshless_key(&rest[at + 1..])
                }
                Some(package) => Some(format!("cargo run -p {package}")),
                None => Some("cargo run".into()),
            },
            _ => None,
        },
        "python" | "python3" => script(rest.first()?),
        "meshless" => meshless_key(rest),
        "meshless-server" => Some(program.to_owned()),
        // Compose's two spellings, the plugin and the standalone tool.
        "docker-compose" => Some("docker-compose".into()),
        "docker" if rest.first() == Some(&"compose") => Some("docker-compose".into()),
        _ => script(program),
    }
}

/// Whether `path` is an executable file under `deploy/` (a script there,
/// such as `deploy/base-images`, beside Dockerfiles and configs that are
/// not commands).
fn is_executable_in_deploy(path: &str) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.starts_with("deploy/")
        && std::fs::metadata(root().join(path))
            .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

/// Every `(key, document)` the documents cite, sorted, without repeats.
fn cited_commands(root: &Path) -> Vec<(String, String)> {
    let mut found: Vec<(String, String)> = documents(root)
        .iter()
        .flat_map(|document| {
            command_texts(&read(root, document))
                .iter()
                .filter_map(|text| command_key(text))
                .map(|key| (key, document.display().to_string()))
                .collect::<Vec<_>>()
        })
        .collect();
    found.sort();
    found.dedup();
    found
}

/// The keys a smoke script names in its `# covers: KEY` lines.
fn covered(script: &str) -> Vec<String> {
    script
        .lines()
        .filter_map(|line| line.trim().strip_prefix(COVERS))
        .map(|key| key.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect()
}

/// The cited `(key, document)` pairs the script does not cover.
fn uncovered(cited: &[(String, String)], script: &str) -> Vec<String> {
    let covered = covered(script);
    cited
        .iter()
        .filter(|(key, _)| !covered.contains(key))
        .map(|(key, document)| format!("{document}: {key}"))
        .collect()
}

#[test]
fn the_command_extractor_keeps_program_and_subcommand_and_skips_prose() {
    let text = "\
Run `cargo run --release -p meshless-cli --
demo` or `meshless study --knob KNOB [--values v1,v2]`; `cargo bench -p
meshless-engine --bench NAME` is a placeholder, `RUSTFLAGS=\"-C target-cpu=x86-64-v3\"
cargo bench -p meshless-engine --bench embedded` is not. Not commands:
`meshless runs at 1.16x`, `meshless import`, `meshless`, `meshless-cli`,
`meshless/v1/sessions/{id}/frames`, `scripts/`, `cargo test -p meshless-tests`.

```bash
target/release/meshless-server --grpc-addr 127.0.0.1:50051
target/release/meshless session run ID --until 2.0   # a comment
python scripts/plot_frames.py out/ply -o a.png
scripts/bench-peers --warmup 24
docker compose -f deploy/compose.yaml up --build --exit-code-from harness harness
deploy/base-images --rebuild
```

```python
from meshless import Client, Frames
```

```
meshless demo: dam break
```
";
    let mut keys: Vec<String> = command_texts(text)
        .iter()
        .filter_map(|t| command_key(t))
        .collect();
    keys.sort();
    assert_eq!(
        keys,
        [
            "cargo bench -p meshless-engine --bench embedded",
            "deploy/base-images",
            "docker-compose",
            "meshless demo",
            "meshless session run",
            "meshless study",
            "meshless-server",
            "scripts/bench-peers",
            "scripts/plot_frames.py",
        ]
    );
}

#[test]
fn an_uncovered_command_is_reported() {
    let cited = [
        ("meshless run".to_owned(), "README.md".to_owned()),
        (
            "scripts/bench-peers".to_owned(),
            "docs/performance.md".to_owned(),
        ),
        ("meshless watch".to_owned(), "README.md".to_owned()),
    ];
    let script = "\
# covers: meshless run
step \"meshless run scenes/dam_break.toml --until 0.02\"
  # covers:   scripts/bench-peers
# meshless watch is mentioned, but not covered
";
    assert_eq!(uncovered(&cited, script), ["README.md: meshless watch"]);
}

#[test]
fn every_command_the_documents_cite_is_smoke_run() {
    let root = root();
    let cited = cited_commands(&root);
    assert!(
        cited.iter().any(|(key, _)| key == "meshless demo"),
        "the extractor found no `meshless demo` in the documents: {cited:?}"
    );
    let script = read(&root, Path::new(SMOKE_SCRIPT));
    let missing = uncovered(&cited, &script);
    assert!(
        missing.is_empty(),
        "the documents cite commands that {SMOKE_SCRIPT} does not smoke-run:\n  {}\n\
         Add a smoke line for each to {SMOKE_SCRIPT}: the command at a tiny size under a \
         `step` header, with a `{COVERS} KEY` comment naming it (the key rules are in \
         tests/tests/docs.rs)",
        missing.join("\n  ")
    );
}
