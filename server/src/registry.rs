//! The sessions a server holds, by id, within its limits.

use crate::error::{ServiceError, quote};
use crate::session::Session;
use meshless_engine::{BuildOptions, Scene};
use std::collections::HashMap;
use std::hash::{BuildHasher, RandomState};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};
use tokio_util::sync::CancellationToken;

#[derive(Debug)]
pub struct Registry {
    sessions: RwLock<HashMap<String, Arc<Session>>>,
    zenoh: zenoh::Session,
    options: BuildOptions,
    max_sessions: u32,
    serial: AtomicU64,
    ids: RandomState,
    cancel: CancellationToken,
}

impl Registry {
    pub fn new(
        zenoh: zenoh::Session,
        options: BuildOptions,
        max_sessions: u32,
        cancel: CancellationToken,
    ) -> Self {
        Self {
            sessions: RwLock::default(),
            zenoh,
            options,
            max_sessions,
            serial: AtomicU64::new(0),
            ids: RandomState::new(),
            cancel,
        }
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

    /// Validates and builds the scene off the async runtime, then starts
    /// its session.
    ///
    /// # Errors
    /// Invalid scenes and exhausted limits; nothing is kept on error.
    pub async fn create(&self, scene: Scene) -> Result<Arc<Session>, ServiceError> {
        let limit = self.max_sessions;
        if self.read().len() >= limit as usize {
            return Err(ServiceError::TooManySessions { limit });
        }
        let options = self.options;
        let world = tokio::task::spawn_blocking(move || scene.build(&options))
            .await
            .map_err(|e| ServiceError::Internal(format!("scene build task failed: {e}")))??;
        let serial = self.serial.fetch_add(1, Ordering::Relaxed);
        let id = format!(
            "{:016x}",
            self.ids.hash_one((serial, std::time::SystemTime::now()))
        );
        let session = Session::start(
            id.clone(),
            serial,
            world,
            options,
            &self.zenoh,
            self.cancel.child_token(),
        )
        .map_err(|e| ServiceError::Internal(format!("cannot start a compute thread: {e}")))?;
        let mut sessions = self.write();
        if sessions.len() >= limit as usize {
            drop(sessions);
            let late = session.clone();
            tokio::task::spawn_blocking(move || late.shut_down());
            return Err(ServiceError::TooManySessions { limit });
        }
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
        join_blocking(session).await;
        Ok(())
    }

    /// Stops every session; used at server shutdown.
    pub async fn shut_down_all(&self) {
        let sessions: Vec<_> = self.write().drain().map(|(_, s)| s).collect();
        for session in sessions {
            join_blocking(session).await;
        }
    }
}

async fn join_blocking(session: Arc<Session>) {
    let id = session.id.clone();
    if let Err(e) = tokio::task::spawn_blocking(move || session.shut_down()).await {
        tracing::error!(session = %id, "shutting the session down failed: {e}");
    }
}
