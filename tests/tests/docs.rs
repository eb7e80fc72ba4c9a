//! The documentation points only at files that exist, the README stays
//! short, and it links every page of `docs/`.
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
