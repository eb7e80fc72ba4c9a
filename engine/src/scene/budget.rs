//! The memory a host lets a scene's check take before it is built: a
//! modal solid's precompute allocates gigabytes inside the check (the
//! shape functions of millions of quadrature points, the assembled
//! matrices), so its estimate ([`crate::efg::Estimate`]) is put to the
//! host's budget before those stages run, not after.

use std::fmt;
use std::sync::Arc;

/// Reserves memory for work a check is about to do, or says why not.
type Reserve = dyn Fn(u64) -> Result<(), String> + Send + Sync;

/// Where a check reserves the memory of what it is about to build. The
/// default reserves nothing and refuses nothing: hosts without a budget
/// (the CLI, tests) pay no cost.
#[derive(Clone, Default)]
pub struct Budget(Option<Arc<Reserve>>);

impl Budget {
    /// A budget that asks `reserve(bytes)` before each expensive stage:
    /// `Ok` holds the bytes for this scene (the host gives them back when
    /// the scene is refused or replaces them by its checked footprint),
    /// `Err` says what the host has left and which of its settings sets
    /// it, in a sentence that follows "and".
    pub fn new(reserve: impl Fn(u64) -> Result<(), String> + Send + Sync + 'static) -> Self {
        Self(Some(Arc::new(reserve)))
    }

    /// Reserves `bytes`, or the host's reason not to.
    pub(crate) fn reserve(&self, bytes: u64) -> Result<(), String> {
        self.0.as_ref().map_or(Ok(()), |reserve| reserve(bytes))
    }
}

impl fmt::Debug for Budget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.is_some() {
            "Budget(host)"
        } else {
            "Budget(unlimited)"
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    #[test]
    fn the_default_refuses_nothing_and_a_host_budget_is_asked() {
        assert_eq!(Budget::default().reserve(u64::MAX), Ok(()));
        let held = Arc::new(AtomicU64::new(0));
        let seen = held.clone();
        let budget = Budget::new(move |bytes| {
            if bytes > 100 {
                return Err("the host has 100 bytes left".into());
            }
            seen.fetch_add(bytes, Ordering::Relaxed);
            Ok(())
        });
        assert_eq!(budget.clone().reserve(60), Ok(()));
        assert!(budget.reserve(101).is_err());
        assert_eq!(held.load(Ordering::Relaxed), 60, "clones share the host's");
    }
}
