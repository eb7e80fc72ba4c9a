//! Who may see and who may drive a session: its owner (the principal
//! that created it), the observers the owner named, and the one client
//! instance that drives it at a time.

use crate::auth::Caller;
use crate::error::ServiceError;
use std::sync::{Arc, Mutex};

/// Observer entry that lets every authenticated principal read.
pub const EVERYONE: &str = "*";
/// Most observers a session may name.
pub const MAX_OBSERVERS: usize = 64;

/// A session's owner, observers and current controller.
#[derive(Debug)]
pub struct Access {
    owner: Arc<str>,
    observers: Vec<String>,
    /// The [`Caller::controller`] that drives the session now.
    controller: Mutex<String>,
}

impl Access {
    /// The access of a session `creator` makes, readable by `observers`
    /// (principal names, or `*` for everyone); the creator drives it.
    pub fn new(creator: &Caller, observers: Vec<String>) -> Self {
        Self {
            owner: creator.principal.clone(),
            observers,
            controller: Mutex::new(creator.controller()),
        }
    }

    /// The access of a session restored from a checkpoint: its owner (no
    /// client instance drives it until one calls) and observers.
    pub fn restored(owner: &str, observers: Vec<String>) -> Self {
        Self {
            owner: owner.into(),
            observers,
            controller: Mutex::new(owner.to_owned()),
        }
    }

    /// Allows only the owner to `action` session `id`, without taking
    /// control of it (a snapshot reads the whole state, a drive changes
    /// it).
    ///
    /// # Errors
    /// [`ServiceError::PermissionDenied`] for anyone but the owner.
    pub fn check_owner(
        &self,
        id: &str,
        caller: &Caller,
        action: &'static str,
    ) -> Result<(), ServiceError> {
        if caller.principal == self.owner {
            Ok(())
        } else {
            Err(self.refuse_drive(id, caller, action))
        }
    }

    /// Why `caller`, not the owner, may not `action` session `id`: an
    /// observer is told it observes (it already sees the session), anyone
    /// else that the session is another's.
    fn refuse_drive(&self, id: &str, caller: &Caller, action: &'static str) -> ServiceError {
        if self.may_read(caller) {
            ServiceError::ObserverMayNotDrive {
                session_id: id.to_owned(),
                action,
                owner: self.owner.to_string(),
            }
        } else {
            ServiceError::PermissionDenied {
                session_id: id.to_owned(),
                action,
            }
        }
    }

    /// The owner's principal.
    pub fn owner(&self) -> &str {
        &self.owner
    }

    /// The observers the owner named.
    pub fn observers(&self) -> &[String] {
        &self.observers
    }

    /// Whether `caller` may see the session: its owner or an observer.
    pub fn may_read(&self, caller: &Caller) -> bool {
        caller.principal == self.owner
            || self
                .observers
                .iter()
                .any(|o| o == EVERYONE || **o == *caller.principal)
    }

    /// Allows `caller` to read session `id`.
    ///
    /// # Errors
    /// [`ServiceError::PermissionDenied`] for anyone but the owner and
    /// the observers.
    pub fn check_read(&self, id: &str, caller: &Caller) -> Result<(), ServiceError> {
        if self.may_read(caller) {
            Ok(())
        } else {
            Err(ServiceError::PermissionDenied {
                session_id: id.to_owned(),
                action: "see",
            })
        }
    }

    /// Allows `caller` to drive (step, run, edit, delete...) session `id`,
    /// making it the controller when it takes over.
    ///
    /// # Errors
    /// [`ServiceError::PermissionDenied`] for anyone but the owner;
    /// [`ServiceError::ControlledElsewhere`] when another client instance
    /// of the owner drives it and `caller` does not take over.
    pub fn check_drive(
        &self,
        id: &str,
        caller: &Caller,
        action: &'static str,
    ) -> Result<(), ServiceError> {
        if caller.principal != self.owner {
            return Err(self.refuse_drive(id, caller, action));
        }
        let me = caller.controller();
        let mut controller = self
            .controller
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if *controller == me {
            return Ok(());
        }
        if caller.take_over {
            tracing::info!(session = %id, from = %controller, to = %me, "control taken over");
            *controller = me;
            return Ok(());
        }
        Err(ServiceError::ControlledElsewhere {
            session_id: id.to_owned(),
            controller: controller.clone(),
        })
    }
}

/// Checks the observers a `CreateSession` names.
///
/// # Errors
/// [`ServiceError::InvalidArgument`] naming `observers[k]`.
pub fn check_observers(observers: &[String]) -> Result<(), ServiceError> {
    if observers.len() > MAX_OBSERVERS {
        return Err(ServiceError::invalid(
            "observers",
            format!(
                "names {} principals; name at most {MAX_OBSERVERS}, or \"*\" for everyone",
                observers.len()
            ),
        ));
    }
    for (k, name) in observers.iter().enumerate() {
        if name != EVERYONE {
            crate::auth::check_name(name).map_err(|e| {
                ServiceError::invalid(format!("observers[{k}]"), format!("{e}, or \"*\""))
            })?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::Code;

    fn caller(principal: &str, client: Option<&str>, take_over: bool) -> Caller {
        Caller {
            principal: principal.into(),
            client: client.map(Into::into),
            take_over,
        }
    }

    #[test]
    fn owners_drive_observers_read_strangers_do_neither() {
        let alice = caller("alice", None, false);
        let access = Access::new(&alice, vec!["bob".into()]);
        let bob = caller("bob", None, false);
        let eve = caller("eve", None, true);
        access.check_read("s", &alice).expect("owner reads");
        access.check_read("s", &bob).expect("observer reads");
        let err = access.check_read("s", &eve).expect_err("stranger");
        assert_eq!(err.code(), Code::PermissionDenied);
        access
            .check_drive("s", &alice, "step")
            .expect("owner drives");
        for stranger in [&bob, &eve] {
            let err = access
                .check_drive("s", stranger, "step")
                .expect_err("not owner");
            assert_eq!(err.code(), Code::PermissionDenied, "{err}");
            assert!(err.to_string().contains("step"), "{err}");
        }
        // The observer is told it observes, not to ask to be named one.
        let told = access.check_drive("s", &bob, "step").expect_err("observer");
        assert!(told.to_string().contains("you observe"), "{told}");
        assert!(told.to_string().contains("`alice`"), "{told}");
        let told = access.check_drive("s", &eve, "step").expect_err("stranger");
        assert!(told.to_string().contains("`observers`"), "{told}");
        let everyone = Access::new(&alice, vec![EVERYONE.into()]);
        everyone.check_read("s", &eve).expect("everyone reads");
    }

    #[test]
    fn one_controller_at_a_time_unless_taken_over() {
        let creator = caller("alice", Some("laptop"), false);
        let access = Access::new(&creator, Vec::new());
        access
            .check_drive("s", &creator, "run")
            .expect("creator drives");
        let notebook = caller("alice", Some("notebook"), false);
        let err = access
            .check_drive("s", &notebook, "run")
            .expect_err("second");
        assert_eq!(err.code(), Code::Aborted);
        assert!(err.to_string().contains("alice/laptop"), "{err}");
        let taking = caller("alice", Some("notebook"), true);
        access.check_drive("s", &taking, "run").expect("take over");
        access
            .check_drive("s", &notebook, "run")
            .expect("now it drives");
        let err = access
            .check_drive("s", &creator, "run")
            .expect_err("lost control");
        assert_eq!(err.code(), Code::Aborted);
    }

    #[test]
    fn observer_lists_are_bounded_and_named() {
        check_observers(&["bob".into(), "*".into()]).expect("valid");
        let err = check_observers(&["bob".into(), "b o b".into()]).expect_err("space");
        assert!(err.to_string().starts_with("observers[1]"), "{err}");
        let many = vec!["x".to_owned(); MAX_OBSERVERS + 1];
        assert!(check_observers(&many).is_err());
        let long = vec!["x".repeat(1000)];
        let err = check_observers(&long).expect_err("long");
        assert!(err.to_string().len() < 200, "{err}");
    }
}
