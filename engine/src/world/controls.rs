//! Runtime controls of a world's systems, apart from the design
//! optimiser: grabs on modal solids (Guo–Qin Section 5.3.3), keyed by
//! system and validated by the system they hold. They act from the next
//! step and are not part of a snapshot: whoever set them sets them again.

use super::World;
use super::system::System;
use crate::efg::{Grab, GrabError};
use std::collections::BTreeMap;

/// Why grabs were refused; the previous ones stay.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GrabsError {
    /// The system is not a modal solid.
    #[error(
        "systems[{system}] is not a modal solid of this world; grabs hold points of a system \
         with kind = \"modal_solid\""
    )]
    NotModal {
        /// The index asked for.
        system: usize,
    },
    /// The solid refused a grab.
    #[error("systems[{system}]: {source}")]
    Grab {
        /// The solid's index.
        system: usize,
        /// Why.
        source: GrabError,
    },
}

impl World {
    /// Holds `grabs` on the modal solid of system `system` besides the
    /// scene's own (Section 5.3.3), replacing those set before; they act
    /// from the next step.
    ///
    /// # Errors
    /// [`GrabsError`] when `system` is not a modal solid or a grab is
    /// refused; the previous grabs then stay.
    pub fn set_grabs(&mut self, system: usize, grabs: &[Grab]) -> Result<(), GrabsError> {
        self.system_mut(system)
            .and_then(System::as_modal_mut)
            .ok_or(GrabsError::NotModal { system })?
            .set_grabs(grabs)
            .map_err(|source| GrabsError::Grab { system, source })
    }

    /// [`Self::set_grabs`] for every modal solid at once, all or nothing:
    /// `grabs` by system (a modal solid it does not name holds only the
    /// scene's grabs).
    ///
    /// # Errors
    /// [`GrabsError`] for the first system refused; every solid then
    /// keeps the grabs it had.
    pub fn set_all_grabs(&mut self, grabs: &BTreeMap<usize, Vec<Grab>>) -> Result<(), GrabsError> {
        if let Some(&system) = grabs
            .keys()
            .find(|s| !self.modal_solids().any(|(m, _)| m == **s))
        {
            return Err(GrabsError::NotModal { system });
        }
        let mut done: Vec<(usize, Vec<Grab>)> = Vec::new();
        for m in self.systems.iter_mut().filter_map(System::as_modal_mut) {
            let before = m.extra_grabs().to_vec();
            let wanted = grabs.get(&m.index).map_or(&[][..], Vec::as_slice);
            if let Err(source) = m.set_grabs(wanted) {
                let failed = m.index;
                for (index, previous) in done {
                    if let Some(m) = self.system_mut(index).and_then(System::as_modal_mut) {
                        // They held before: they hold again.
                        let _ = m.set_grabs(&previous);
                    }
                }
                return Err(GrabsError::Grab {
                    system: failed,
                    source,
                });
            }
            done.push((m.index, before));
        }
        Ok(())
    }
}
