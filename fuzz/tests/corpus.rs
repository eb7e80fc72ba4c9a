//! Replays every checked-in fuzz input through the target it was found
//! by: the minimised corpus (`fuzz/corpus/TARGET/`) and the reproducers
//! of fixed defects (`fuzz/regressions/TARGET/`), so that `cargo test`
//! guards what the fuzzers found with no cargo-fuzz installed. A target
//! panics only when one of its properties fails, and the panic names the
//! file.

use std::path::{Path, PathBuf};

/// The files directly under `dir`, sorted; none when it does not exist.
fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .map(|e| e.expect("a readable directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

/// Runs each of `target`'s inputs under `kind`, returning how many ran.
fn replay(kind: &str, target: &str, run: fn(&[u8])) -> usize {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(kind)
        .join(target);
    let inputs = files(&dir);
    for input in &inputs {
        let bytes = std::fs::read(input).expect("a readable input");
        let outcome = std::panic::catch_unwind(|| run(&bytes));
        assert!(
            outcome.is_ok(),
            "{target} fails on {} (see the panic above)",
            input.display()
        );
    }
    inputs.len()
}

/// Every target has a corpus, and all of it passes.
#[test]
fn every_corpus_input_passes() {
    for &(target, run) in meshless_fuzz::TARGETS {
        let count = replay("corpus", target, run);
        assert!(count > 0, "fuzz/corpus/{target}/ holds no input");
    }
}

/// Every reproducer of a fixed defect passes, and each sits under a
/// target that exists.
#[test]
fn every_regression_passes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("regressions");
    for dir in std::fs::read_dir(&root).into_iter().flatten() {
        let name = dir.expect("a readable entry").file_name();
        let name = name.to_string_lossy();
        assert!(
            meshless_fuzz::TARGETS.iter().any(|&(t, _)| t == name),
            "fuzz/regressions/{name}/ names no target"
        );
    }
    for &(target, run) in meshless_fuzz::TARGETS {
        replay("regressions", target, run);
    }
}
