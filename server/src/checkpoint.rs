//! Checkpoints: each session's snapshot written to a directory every
//! interval, and read back when the server starts, so that a server that
//! crashed (or was killed) comes back with its sessions, their ids and
//! owners, losing at most one interval.
//!
//! A checkpoint is written to a temporary file, flushed to disk, then
//! renamed over the last one: a crash mid-write leaves the previous
//! checkpoint whole and a temporary file that the next start removes,
//! never a half-written checkpoint under a checkpoint's name. A session
//! that has not changed since its last checkpoint is not written again;
//! a deleted session's checkpoint is removed with it.

use crate::files::FileError;
use crate::metrics::Metrics;
use crate::registry::Registry;
use crate::session::{Access, Decoded, Session, encode_snapshot};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};
use tokio_util::sync::CancellationToken;

/// Extension of a checkpoint file: `<session id>.snapshot`.
const EXTENSION: &str = "snapshot";
/// Extension of a checkpoint being written.
const TEMPORARY: &str = "tmp";
/// What a checkpoint that cannot be restored is renamed to, kept for
/// whoever wants to look at it.
const REJECTED: &str = "rejected";

/// Shortest wait for one session's snapshot in a round.
const MIN_WAIT: Duration = Duration::from_secs(1);

/// What identifies a session's state: unchanged, no new checkpoint.
#[derive(Debug, Clone, PartialEq)]
struct Fingerprint {
    step: u64,
    state: i32,
    reason: String,
    design: u64,
}

fn fingerprint(session: &Session) -> Fingerprint {
    let status = session.status();
    Fingerprint {
        step: status.step,
        state: status.state,
        reason: status.reason,
        design: session.design_revision(),
    }
}

/// Replaces the file at `path` with what `write` writes: into
/// `temporary`, flushed to disk, renamed over `path`. On any failure (a
/// full disk, a path that cannot be replaced) the temporary file is
/// removed, so that it neither takes the space the next write needs nor
/// outlives the failure, and `path` keeps what it held.
///
/// # Errors
/// The first I/O error.
fn replace(
    temporary: &Path,
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let written = std::fs::File::create(temporary).and_then(|mut file| {
        write(&mut file)?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(temporary, path)
    });
    if written.is_err() {
        match std::fs::remove_file(temporary) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(
                file = %temporary.display(),
                "cannot remove an unfinished checkpoint: {e}"
            ),
        }
    }
    written
}

/// The checkpoint directory, its interval and what was last written.
#[derive(Debug)]
pub struct Checkpoints {
    dir: PathBuf,
    interval: Duration,
    limit: usize,
    written: Mutex<HashMap<String, Fingerprint>>,
    /// When the last round finished, for the checkpoint-age metric.
    last_round: Mutex<Option<SystemTime>>,
    metrics: Arc<Metrics>,
    /// Held by the round in progress: the periodic one and the last one
    /// of a shutdown never write the same file at once.
    writing: tokio::sync::Mutex<()>,
}

impl Checkpoints {
    /// Checkpoints in `dir` (created if missing) every `interval`, each at
    /// most `limit` bytes.
    ///
    /// # Errors
    /// A directory that cannot be created.
    pub fn new(
        dir: &Path,
        interval: Duration,
        limit: usize,
        metrics: Arc<Metrics>,
    ) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        Ok(Self {
            dir: dir.to_owned(),
            interval,
            limit,
            written: Mutex::default(),
            last_round: Mutex::default(),
            metrics,
            writing: tokio::sync::Mutex::default(),
        })
    }

    fn written(&self) -> std::sync::MutexGuard<'_, HashMap<String, Fingerprint>> {
        self.written
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// When the last round finished, if one has.
    pub fn last_round(&self) -> Option<SystemTime> {
        *self
            .last_round
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn path(&self, id: &str, extension: &str) -> PathBuf {
        self.dir.join(format!("{id}.{extension}"))
    }

    /// Restores every checkpoint of the directory into `registry`, with
    /// its id and owner; removes temporary files of a write that never
    /// finished, and renames a checkpoint that cannot be restored to
    /// `*.rejected` (with a warning) so that it never blocks a start.
    /// Returns how many sessions came back.
    pub async fn restore_all(&self, registry: &Registry) -> usize {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) => {
                tracing::warn!(dir = %self.dir.display(), "cannot read the checkpoint directory: {e}");
                return 0;
            }
        };
        let mut restored = 0;
        for entry in entries.flatten() {
            let path = entry.path();
            match path.extension().and_then(|e| e.to_str()) {
                Some(TEMPORARY) => {
                    tracing::info!(file = %path.display(), "removing an unfinished checkpoint");
                    let _ = std::fs::remove_file(&path);
                }
                Some(EXTENSION) => match self.restore_one(registry, &path).await {
                    Ok(session) => {
                        self.written()
                            .insert(session.id.clone(), fingerprint(&session));
                        tracing::info!(
                            session = %session.id,
                            owner = %session.access.owner(),
                            step = session.status().step,
                            "session restored from its checkpoint"
                        );
                        restored += 1;
                        self.metrics.restore();
                    }
                    Err(e) => {
                        let aside = path.with_extension(REJECTED);
                        tracing::warn!(
                            file = %path.display(),
                            kept_as = %aside.display(),
                            "checkpoint not restored: {e}"
                        );
                        let _ = std::fs::rename(&path, &aside);
                    }
                },
                _ => {}
            }
        }
        restored
    }

    async fn restore_one(&self, registry: &Registry, path: &Path) -> anyhow::Result<Arc<Session>> {
        let (path, limit) = (path.to_owned(), self.limit);
        let decoded = tokio::task::spawn_blocking(move || {
            // A regular file within the snapshot limit only: a link to
            // `/dev/zero` or a FIFO is refused, not read for ever.
            let data = crate::files::read_regular(&path, limit as u64).map_err(|e| match e {
                FileError::TooLarge { .. } => {
                    anyhow::anyhow!("{e} (the snapshot limit, --max-snapshot-mb)")
                }
                FileError::Io(_) | FileError::NotRegular { .. } => anyhow::Error::new(e),
            })?;
            let decoded = Decoded::from_blob(&data, limit)?;
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
            if stem != decoded.record.id {
                anyhow::bail!("it holds session {:?}, not {stem:?}", decoded.record.id);
            }
            Ok(decoded)
        })
        .await??;
        let access = Access::restored(&decoded.record.owner, decoded.record.observers.clone());
        let id = decoded.record.id.clone();
        Ok(registry.restore(decoded, access, Some(id)).await?)
    }

    /// Writes the checkpoint of every session that changed since its
    /// last one, and removes those of sessions that are gone.
    pub async fn round(&self, registry: &Registry) {
        let _writing = self.writing.lock().await;
        let sessions = registry.list();
        for session in &sessions {
            let print = fingerprint(session);
            if self.written().get(&session.id) == Some(&print) {
                continue;
            }
            // A session busy with a long `Step` answers only after it: it
            // waits for the next round rather than holding up the others.
            let written = tokio::time::timeout(self.interval.max(MIN_WAIT), self.write(session))
                .await
                .unwrap_or_else(|_| {
                    Err(anyhow::anyhow!(
                        "the session did not answer within an interval (a long Step?); the \
                         next round tries again"
                    ))
                });
            match written {
                Ok(bytes) => {
                    tracing::debug!(session = %session.id, bytes, "checkpoint written");
                    self.metrics.snapshot();
                    self.written().insert(session.id.clone(), print);
                }
                Err(e) => {
                    // The last good checkpoint stays; the next round tries
                    // again, and the other sessions are written meanwhile.
                    self.metrics.checkpoint_failed();
                    tracing::warn!(
                        session = %session.id,
                        "checkpoint not written (the last one written stays): {e:#}"
                    );
                }
            }
        }
        let live: std::collections::HashSet<&str> =
            sessions.iter().map(|s| s.id.as_str()).collect();
        let gone: Vec<String> = self
            .written()
            .keys()
            .filter(|id| !live.contains(id.as_str()))
            .cloned()
            .collect();
        for id in gone {
            self.forget(&id);
        }
        *self
            .last_round
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(SystemTime::now());
    }

    /// Writes `session`'s checkpoint: temporary file, flushed, renamed.
    async fn write(&self, session: &Session) -> anyhow::Result<usize> {
        let payload = session.snapshot().await?;
        let limit = self.limit;
        let (path, temporary, dir) = (
            self.path(&session.id, EXTENSION),
            self.path(&session.id, TEMPORARY),
            self.dir.clone(),
        );
        tokio::task::spawn_blocking(move || {
            let data = encode_snapshot(&payload, limit)?;
            replace(&temporary, &path, |file| {
                std::io::Write::write_all(file, &data)
            })?;
            // The rename itself reaches the disk with the directory.
            if let Ok(dir) = std::fs::File::open(&dir) {
                let _ = dir.sync_all();
            }
            Ok(data.len())
        })
        .await?
    }

    /// Removes session `id`'s checkpoint (the session was deleted).
    pub fn forget(&self, id: &str) {
        self.written().remove(id);
        match std::fs::remove_file(self.path(id, EXTENSION)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(session = %id, "cannot remove the checkpoint: {e}"),
        }
    }

    /// Writes a round every interval until `stop`. The server writes one
    /// last round itself before it stops the sessions, so a graceful
    /// shutdown loses nothing.
    pub fn spawn(
        self: Arc<Self>,
        registry: Arc<Registry>,
        stop: CancellationToken,
    ) -> tokio::task::JoinHandle<()> {
        tokio::spawn(async move {
            let mut ticks = tokio::time::interval_at(
                tokio::time::Instant::now() + self.interval,
                self.interval,
            );
            ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tokio::select! {
                    _ = ticks.tick() => {}
                    () = stop.cancelled() => break,
                }
                let started = Instant::now();
                self.round(&registry).await;
                tracing::trace!(took = ?started.elapsed(), "checkpoint round");
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A write that fails part of the way (here, as on a full disk)
    /// leaves no temporary file and the previous checkpoint whole.
    #[test]
    fn a_failed_write_removes_its_temporary_file_and_keeps_the_last_checkpoint() {
        let dir = std::env::temp_dir().join(format!("meshless-replace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let (path, temporary) = (dir.join("s.snapshot"), dir.join("s.tmp"));
        replace(&temporary, &path, |f| std::io::Write::write_all(f, b"good")).expect("written");
        let full = replace(&temporary, &path, |f| {
            std::io::Write::write_all(f, b"half")?;
            Err(std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                "No space left on device",
            ))
        });
        assert_eq!(
            full.expect_err("the injected error").kind(),
            std::io::ErrorKind::StorageFull
        );
        assert!(
            !temporary.exists(),
            "the temporary file outlived the failure"
        );
        assert_eq!(std::fs::read(&path).expect("kept"), b"good");
        replace(&temporary, &path, |f| std::io::Write::write_all(f, b"next")).expect("written");
        assert_eq!(std::fs::read(&path).expect("written"), b"next");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
