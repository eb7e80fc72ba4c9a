//! The sessions a server holds, by id, within its limits.

use crate::error::{ServiceError, quote};
use crate::metrics::Metrics;
use crate::session::{Access, Decoded, Origin, Outlet, Session, snapshot_unfit};
use meshless_engine::scene::Checked;
use meshless_engine::{Budget, BuildOptions, Cancel, Scene, WorldState};
use meshless_proto::seal::Sealer;
use meshless_proto::v1;
use std::collections::HashMap;
use std::hash::{BuildHasher, RandomState};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use tokio_util::sync::CancellationToken;

#[derive(Debug)]
pub struct Registry {
    sessions: RwLock<HashMap<String, Arc<Session>>>,
    zenoh: zenoh::Session,
    /// Whether each session seals its zenoh payloads with a key of its own.
    seal: bool,
    options: BuildOptions,
    max_sessions: u32,
    /// Shared with the budget a check reserves through (see
    /// [`Registry::admit`]), which may outlive the admission it serves.
    memory: Arc<Mutex<Memory>>,
    serial: AtomicU64,
    ids: RandomState,
    /// What every id this server makes starts with: `NAME-` with a
    /// `--server-name`, else nothing.
    id_prefix: String,
    cancel: CancellationToken,
    metrics: Arc<Metrics>,
}

impl Registry {
    pub fn new(
        zenoh: zenoh::Session,
        seal: bool,
        options: BuildOptions,
        max_sessions: u32,
        memory_budget: u64,
        cancel: CancellationToken,
        metrics: Arc<Metrics>,
    ) -> Self {
        Self {
            sessions: RwLock::default(),
            zenoh,
            seal,
            options,
            max_sessions,
            memory: Arc::new(Mutex::new(Memory {
                budget: memory_budget,
                reserved: 0,
                by_session: HashMap::new(),
            })),
            serial: AtomicU64::new(0),
            ids: RandomState::new(),
            id_prefix: String::new(),
            cancel,
            metrics,
        }
    }

    /// Makes every new session id start with `name-`, so that clients can
    /// tell which replica holds a session from its id alone.
    #[must_use]
    pub fn named(mut self, name: Option<&str>) -> Self {
        self.id_prefix = name.map(|n| format!("{n}-")).unwrap_or_default();
        self
    }

    fn memory(&self) -> std::sync::MutexGuard<'_, Memory> {
        lock(&self.memory)
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, HashMap<String, Arc<Session>>> {
        self.sessions
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn write(&self) -> std::sync::RwLockWriteGuard<'_, HashMap<String, Arc<Session>>> {
        self.sessions
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The zenoh session every session publishes through.
    pub fn zenoh(&self) -> &zenoh::Session {
        &self.zenoh
    }

    /// The limits and the mesh-file policy sessions are built with.
    pub fn options(&self) -> &BuildOptions {
        &self.options
    }

    /// Validates and builds the scene off the async runtime, then starts
    /// its session.
    ///
    /// # Errors
    /// Invalid scenes and exhausted limits; nothing is kept on error.
    pub async fn create(&self, scene: Scene, access: Access) -> Result<Arc<Session>, ServiceError> {
        self.admit(scene, None, access, None).await
    }

    /// Starts a session from a decoded snapshot: its scene built, then
    /// moved to the snapshot's state. `id` keeps the snapshot's id (a
    /// checkpoint restored at start); `None` makes a new one.
    ///
    /// # Errors
    /// As [`Self::create`], and a snapshot that does not fit its scene, or
    /// an id already taken.
    pub async fn restore(
        &self,
        snapshot: Decoded,
        access: Access,
        id: Option<String>,
    ) -> Result<Arc<Session>, ServiceError> {
        if let Some(id) = &id {
            check_id(id)?;
            if !self.id_prefix.is_empty() && !id.starts_with(&self.id_prefix) {
                // Clients route by the id's prefix, which names another
                // replica: its checkpoint volume was moved here.
                tracing::warn!(
                    session = %id,
                    "restored a session whose id names another server; clients routing by id \
                     will look for it there"
                );
            }
            if self.read().contains_key(id) {
                return Err(ServiceError::invalid(
                    "session_id",
                    format!("a session with id {} already exists", quote(id)),
                ));
            }
        }
        self.admit(snapshot.scene.clone(), Some(snapshot), access, id)
            .await
    }

    /// Moves `session` to `snapshot` (of the session's own scene). Its
    /// reservation first grows to what the restored state holds by
    /// estimate, its positions checked, as a restore into a new session
    /// reserves: a forged state may pile particles its scene's lattice
    /// never would. A refused restore gives the growth back.
    ///
    /// # Errors
    /// As [`Session::restore`], and [`ServiceError::MemoryBudget`] when
    /// the growth does not fit. Nothing changes on error.
    pub async fn restore_into(
        &self,
        session: &Session,
        snapshot: Decoded,
    ) -> Result<v1::SessionStatus, ServiceError> {
        session.check_scene(&snapshot)?;
        let (scene, options) = (session.scene.clone(), self.options.clone());
        let (checked, snapshot, needed) = tokio::task::spawn_blocking(move || {
            let (checked, needed) = check(scene, &options, Some(&snapshot.world))?;
            Ok::<_, ServiceError>((checked, snapshot, needed))
        })
        .await
        .map_err(|e| ServiceError::Internal(format!("scene check task failed: {e}")))??;
        let held = self.memory().grow(&session.id, needed)?;
        let restored = session.restore(snapshot, checked, &self.options).await;
        if restored.is_err() {
            self.memory().shrink(&session.id, held);
        }
        restored
    }

    /// Checks, reserves, builds (and restores `snapshot` into) a world
    /// for `scene` off the async runtime, then starts its session.
    async fn admit(
        &self,
        scene: Scene,
        snapshot: Option<Decoded>,
        access: Access,
        id: Option<String>,
    ) -> Result<Arc<Session>, ServiceError> {
        let limit = self.max_sessions;
        if self.read().len() >= limit as usize {
            return Err(ServiceError::TooManySessions { limit });
        }
        let mut options = self.options.clone();
        // The check may run a modal solid's precompute for seconds: when
        // the caller goes (this future is dropped), it stops.
        options.cancel = Cancel::new();
        let _stop = options.cancel.raise_on_drop();
        // A modal solid's precompute is built inside the check: its
        // estimate is reserved there, before the allocation, through
        // `early`, which gives it back when the check fails or is dropped.
        let early = Arc::new(Early {
            memory: self.memory.clone(),
            bytes: AtomicU64::new(0),
        });
        options.budget = early.budget();
        // Validation and the estimate first (a mesh may be read), then the
        // reservation, and only then the allocation.
        let (checked, snapshot, needed) = tokio::task::spawn_blocking(move || {
            let (checked, needed) = check(scene, &options, snapshot.as_ref().map(|s| &s.world))?;
            Ok::<_, ServiceError>((checked, snapshot, needed))
        })
        .await
        .map_err(|e| ServiceError::Internal(format!("scene check task failed: {e}")))??;
        // The checked footprint replaces the early reservation, under one
        // lock so that no other admission sees the bytes free between.
        {
            let mut memory = self.memory();
            memory.release_unassigned(early.bytes.swap(0, Ordering::Relaxed));
            memory.reserve(needed)?;
        }
        let serial = self.serial.fetch_add(1, Ordering::Relaxed);
        let id = id.unwrap_or_else(|| {
            format!(
                "{}{:016x}",
                self.id_prefix,
                self.ids.hash_one((serial, std::time::SystemTime::now()))
            )
        });
        let options = self.options.clone();
        let built = tokio::task::spawn_blocking(move || {
            let world = checked.build();
            match snapshot {
                None => Ok(Origin::Built(Box::new(world))),
                Some(snapshot) => Ok(Origin::Restored(Box::new(
                    snapshot.resume(world, &options)?,
                ))),
            }
        })
        .await
        .map_err(|e| ServiceError::Internal(format!("scene build task failed: {e}")))
        .and_then(|built| built);
        let origin = match built {
            Ok(origin) => origin,
            Err(e) => {
                self.memory().release_unassigned(needed);
                return Err(e);
            }
        };
        let sealer = match self.seal.then(Sealer::generate).transpose() {
            Ok(sealer) => sealer.map(Arc::new),
            Err(e) => {
                self.memory().release_unassigned(needed);
                return Err(ServiceError::Internal(format!(
                    "cannot make a seal key: {e}"
                )));
            }
        };
        let outlet = Outlet {
            zenoh: self.zenoh.clone(),
            sealer,
            metrics: self.metrics.clone(),
        };
        let started = Session::start(
            id.clone(),
            serial,
            origin,
            self.options.clone(),
            outlet,
            self.cancel.child_token(),
            access,
        );
        let session = match started {
            Ok(session) => session,
            Err(e) => {
                self.memory().release_unassigned(needed);
                return Err(ServiceError::Internal(format!(
                    "cannot start a compute thread: {e}"
                )));
            }
        };
        let mut sessions = self.write();
        let refused = if sessions.len() >= limit as usize {
            Some(ServiceError::TooManySessions { limit })
        } else if sessions.contains_key(&id) {
            Some(ServiceError::invalid(
                "session_id",
                format!("a session with id {} already exists", quote(&id)),
            ))
        } else {
            None
        };
        if let Some(error) = refused {
            drop(sessions);
            self.memory().release_unassigned(needed);
            let late = session.clone();
            tokio::task::spawn_blocking(move || late.shut_down());
            return Err(error);
        }
        self.memory().assign(&id, needed);
        sessions.insert(id, session.clone());
        Ok(session)
    }

    /// # Errors
    /// [`ServiceError::NotFound`] for an unknown id.
    pub fn get(&self, id: &str) -> Result<Arc<Session>, ServiceError> {
        self.read()
            .get(id)
            .cloned()
            .ok_or_else(|| ServiceError::NotFound(quote(id)))
    }

    /// All sessions, oldest first.
    pub fn list(&self) -> Vec<Arc<Session>> {
        let mut all: Vec<_> = self.read().values().cloned().collect();
        all.sort_by_key(|s| s.serial);
        all
    }

    /// Removes a session and stops its compute thread.
    ///
    /// # Errors
    /// [`ServiceError::NotFound`] for an unknown id.
    pub async fn delete(&self, id: &str) -> Result<(), ServiceError> {
        let session = self
            .write()
            .remove(id)
            .ok_or_else(|| ServiceError::NotFound(quote(id)))?;
        self.memory().release(id);
        join_blocking(session).await;
        Ok(())
    }

    /// Stops every session; used at server shutdown.
    pub async fn shut_down_all(&self) {
        let sessions: Vec<_> = self.write().drain().map(|(_, s)| s).collect();
        for session in sessions {
            self.memory().release(&session.id);
            join_blocking(session).await;
        }
    }
}

/// Checks `scene` (and the positions of `restored`, a state it is to
/// move to), and says how many bytes its world will hold by estimate: the
/// restored state's neighbour pairs where there is one, since a forged
/// state may pile particles the scene's lattice never would. Blocking.
fn check(
    scene: Scene,
    options: &BuildOptions,
    restored: Option<&WorldState>,
) -> Result<(Checked, u64), ServiceError> {
    let checked = scene.check(options)?;
    let footprint = match restored {
        None => checked.footprint(),
        Some(state) => checked
            .restored_footprint(state)
            .map_err(|e| snapshot_unfit(&e))?,
    };
    let needed = footprint.bytes.ceil().min(u64::MAX as f64) as u64;
    Ok((checked, needed))
}

fn lock(memory: &Mutex<Memory>) -> std::sync::MutexGuard<'_, Memory> {
    memory
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What a scene's check reserved before its precompute ran
/// ([`meshless_engine::Budget`]): held until the admission replaces it by
/// the checked footprint, and given back when it is dropped (by the
/// admission and by the check's own copy of the budget), so a refused,
/// failed or abandoned check leaves the budget as it found it.
#[derive(Debug)]
struct Early {
    memory: Arc<Mutex<Memory>>,
    bytes: AtomicU64,
}

impl Early {
    /// The budget a check reserves through: the memory's free bytes, or a
    /// refusal saying what is left and which setting to raise.
    fn budget(self: &Arc<Self>) -> Budget {
        let early = self.clone();
        Budget::new(move |bytes| {
            lock(&early.memory).reserve(bytes).map_err(|e| match e {
                ServiceError::MemoryBudget {
                    free_mb, budget_mb, ..
                } => format!(
                    "the server has {free_mb} MB of its {budget_mb} MB memory budget \
                     (--memory-budget-mb) left"
                ),
                other => other.to_string(),
            })?;
            early.bytes.fetch_add(bytes, Ordering::Relaxed);
            Ok(())
        })
    }
}

impl Drop for Early {
    fn drop(&mut self) {
        lock(&self.memory).release_unassigned(*self.bytes.get_mut());
    }
}

/// Longest session id a snapshot may carry.
const MAX_ID_LEN: usize = 64;

/// Checks a session id that came from a snapshot: checkpoint files are
/// named after ids, so only letters, digits, `-` and `_`.
fn check_id(id: &str) -> Result<(), ServiceError> {
    let fine = !id.is_empty()
        && id.len() <= MAX_ID_LEN
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if fine {
        Ok(())
    } else {
        Err(ServiceError::invalid(
            "session_id",
            format!(
                "{} is not a session id: 1 to {MAX_ID_LEN} letters, digits, '-' or '_'",
                quote(id)
            ),
        ))
    }
}

/// The memory budget and what the sessions hold of it, by their
/// estimates: a scene is admitted only when its estimate fits what is
/// left, reserved before its world is allocated.
#[derive(Debug)]
struct Memory {
    budget: u64,
    reserved: u64,
    by_session: HashMap<String, u64>,
}

impl Memory {
    /// Reserves `bytes`, or says how much the budget has left.
    fn reserve(&mut self, bytes: u64) -> Result<(), ServiceError> {
        let free = self.budget.saturating_sub(self.reserved);
        if bytes > free {
            let mb = |b: u64| b.div_ceil(1 << 20);
            return Err(ServiceError::MemoryBudget {
                needed_mb: mb(bytes),
                free_mb: free >> 20,
                budget_mb: self.budget >> 20,
            });
        }
        self.reserved += bytes;
        Ok(())
    }

    /// Gives back a reservation no session took.
    fn release_unassigned(&mut self, bytes: u64) {
        self.reserved = self.reserved.saturating_sub(bytes);
    }

    /// Records that session `id` holds a reservation of `bytes`.
    fn assign(&mut self, id: &str, bytes: u64) {
        self.by_session.insert(id.to_owned(), bytes);
    }

    /// Grows what session `id` holds to `bytes` (never shrinks it: the
    /// world it holds until a restore is swapped in is the old one), or
    /// says how much the budget has left. Returns what it held before.
    fn grow(&mut self, id: &str, bytes: u64) -> Result<u64, ServiceError> {
        let held = self.by_session.get(id).copied().unwrap_or(0);
        if bytes > held {
            self.reserve(bytes - held)?;
            self.by_session.insert(id.to_owned(), bytes);
        }
        Ok(held)
    }

    /// Gives back what session `id` holds above `bytes`.
    fn shrink(&mut self, id: &str, bytes: u64) {
        if let Some(held) = self.by_session.get_mut(id) {
            self.reserved = self.reserved.saturating_sub(held.saturating_sub(bytes));
            *held = (*held).min(bytes);
        }
    }

    /// Gives back what session `id` held.
    fn release(&mut self, id: &str) {
        if let Some(bytes) = self.by_session.remove(id) {
            self.reserved = self.reserved.saturating_sub(bytes);
        }
    }
}

async fn join_blocking(session: Arc<Session>) {
    let id = session.id.clone();
    if let Err(e) = tokio::task::spawn_blocking(move || session.shut_down()).await {
        tracing::error!(session = %id, "shutting the session down failed: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reservations_fit_the_budget_and_come_back() {
        let mut memory = Memory {
            budget: 10 << 20,
            reserved: 0,
            by_session: HashMap::new(),
        };
        memory.reserve(6 << 20).expect("fits");
        memory.assign("a", 6 << 20);
        let err = memory.reserve(5 << 20).expect_err("over");
        assert!(err.to_string().contains("needs about 5 MB"), "{err}");
        assert!(err.to_string().contains("4 MB of its 10 MB"), "{err}");
        memory.reserve(4 << 20).expect("the rest fits");
        memory.release_unassigned(4 << 20);
        // A restore into "a" grows what it holds, within the budget only,
        // and a refused restore gives the growth back.
        let err = memory.grow("a", 11 << 20).expect_err("past the budget");
        assert!(err.to_string().contains("4 MB of its 10 MB"), "{err}");
        assert_eq!(memory.grow("a", 9 << 20).expect("fits"), 6 << 20);
        assert_eq!(memory.reserved, 9 << 20);
        assert_eq!(memory.grow("a", 2 << 20).expect("held"), 9 << 20);
        memory.shrink("a", 6 << 20);
        assert_eq!(memory.reserved, 6 << 20);
        memory.release("a");
        memory.release("a");
        assert_eq!(memory.reserved, 0);
        memory.reserve(10 << 20).expect("all of it again");
    }
}
