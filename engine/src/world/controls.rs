//! Runtime controls of a world's systems, apart from the design
//! optimiser: named grabs on modal solids and shells (Guo–Qin Section
//! 5.3.3), each keyed by its system and validated by the system it holds
//! (`Simulated::set_runtime_grabs`). The world
//! keeps the set in force ([`World::controls`]) and replaces it all or
//! nothing ([`World::set_controls`]); they act from the next step. A
//! world built or restored afresh holds none: whoever keeps them (a
//! session, with its snapshots and checkpoints) sets them again.

use super::World;
use super::system::GrabRefusal;
use crate::efg::Grab;
use std::collections::BTreeMap;

/// A named runtime control of one of the world's systems.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Control {
    /// Index of the controlled system in the scene.
    pub system: usize,
    /// What it does.
    pub kind: ControlKind,
}

/// The kinds of runtime control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlKind {
    /// A material point of a modal solid held at a position, an
    /// orientation or both, or of a shell held at a position (rest shape,
    /// world frame).
    Grab(Grab),
}

/// Named controls, listed in name order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Controls {
    items: BTreeMap<String, Control>,
}

impl Controls {
    /// No control.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds or replaces the control called `name`; returns the one it
    /// replaced.
    pub fn insert(&mut self, name: impl Into<String>, control: Control) -> Option<Control> {
        self.items.insert(name.into(), control)
    }

    /// Removes the control called `name`, if any.
    pub fn remove(&mut self, name: &str) -> Option<Control> {
        self.items.remove(name)
    }

    /// The control called `name`, if any.
    pub fn get(&self, name: &str) -> Option<&Control> {
        self.items.get(name)
    }

    /// The controls with their names, in name order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Control)> {
        self.items.iter().map(|(name, c)| (name.as_str(), c))
    }

    /// The number of controls.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether there is no control.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// Each system's grabs with their names, in name order.
    fn grabs(&self) -> BTreeMap<usize, Vec<(&str, Grab)>> {
        let mut by_system: BTreeMap<usize, Vec<(&str, Grab)>> = BTreeMap::new();
        for (name, c) in self.iter() {
            match c.kind {
                ControlKind::Grab(g) => by_system.entry(c.system).or_default().push((name, g)),
            }
        }
        by_system
    }
}

/// Why a set of controls was refused; the world keeps the controls it
/// had.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    /// A control has an empty name.
    #[error("a control has an empty name; give every control a name")]
    Unnamed,
    /// The system a grab names is no system a grab holds.
    #[error(
        "control `{name}`: systems[{system}] is not a modal solid or a shell of this world; \
         grabs hold points of a system with kind = \"modal_solid\" or \"shell\""
    )]
    NotGrabbable {
        /// The control's name.
        name: String,
        /// The index it names.
        system: usize,
    },
    /// The system refused a grab; `name` is the grab at fault, or says
    /// that the system refused its grabs together (too many rows) or one
    /// of the scene's own.
    #[error("control `{name}` on systems[{system}]: {reason}")]
    Grab {
        /// The grab at fault.
        name: String,
        /// The system's index.
        system: usize,
        /// Why, and what to change.
        reason: String,
    },
}

impl World {
    /// The runtime controls in force, by name.
    pub fn controls(&self) -> &Controls {
        &self.controls
    }

    /// Replaces the runtime controls with `controls`, all or nothing: each
    /// system a grab holds (modal solids, shells) holds its scene's grabs
    /// and the grabs `controls` name for it, from the next step.
    ///
    /// # Errors
    /// [`ControlError`] for the first control refused; every system then
    /// keeps what it held and [`Self::controls`] is unchanged.
    pub fn set_controls(&mut self, controls: Controls) -> Result<(), ControlError> {
        if controls.items.keys().any(|name| name.trim().is_empty()) {
            return Err(ControlError::Unnamed);
        }
        let wanted = controls.grabs();
        if let Some((name, system)) = wanted.iter().find_map(|(&system, grabs)| {
            let grabbable = self
                .system(system)
                .is_some_and(|s| s.simulated().scene_grab_count().is_some());
            (!grabbable).then(|| (grabs[0].0.to_owned(), system))
        }) {
            return Err(ControlError::NotGrabbable { name, system });
        }
        let mut done: Vec<(usize, Vec<Grab>)> = Vec::new();
        let mut refused = None;
        for system in &mut self.systems {
            let held = system.simulated_mut();
            let Some(scene_grabs) = held.scene_grab_count() else {
                continue;
            };
            let index = held.index();
            let named = wanted.get(&index).map_or(&[][..], Vec::as_slice);
            let grabs: Vec<Grab> = named.iter().map(|&(_, g)| g).collect();
            let before = held.runtime_grabs();
            if let Err(refusal) = held.set_runtime_grabs(&grabs) {
                refused = Some(ControlError::Grab {
                    name: grab_name(&refusal, scene_grabs, named),
                    system: index,
                    reason: refusal.reason,
                });
                break;
            }
            done.push((index, before));
        }
        if let Some(error) = refused {
            for (index, previous) in done {
                if let Some(system) = self.system_mut(index) {
                    // They held before: they hold again.
                    let _ = system.simulated_mut().set_runtime_grabs(&previous);
                }
            }
            return Err(error);
        }
        self.controls = controls;
        Ok(())
    }
}

/// The name of the grab a system's refusal points at: its index counts
/// the scene's grabs first, then the named ones.
fn grab_name(refusal: &GrabRefusal, scene_grabs: usize, named: &[(&str, Grab)]) -> String {
    let Some(index) = refusal.index else {
        return "(the system's grabs together)".into();
    };
    match index.checked_sub(scene_grabs) {
        Some(k) => named
            .get(k)
            .map_or_else(String::new, |(name, _)| (*name).to_owned()),
        None => format!("(the scene's grabs[{index}])"),
    }
}
