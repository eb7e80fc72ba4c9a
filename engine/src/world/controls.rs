//! Runtime controls of a world's systems, apart from the design
//! optimiser: named grabs on modal solids (Guo–Qin Section 5.3.3), each
//! keyed by its system and validated by the system it holds. The world
//! keeps the set in force ([`World::controls`]) and replaces it all or
//! nothing ([`World::set_controls`]); they act from the next step. A
//! world built or restored afresh holds none: whoever keeps them (a
//! session, with its snapshots and checkpoints) sets them again.

use super::World;
use super::system::System;
use crate::efg::{Grab, GrabError};
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
    /// orientation or both (rest shape, world frame).
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
    /// The system a grab names is not a modal solid.
    #[error(
        "control `{name}`: systems[{system}] is not a modal solid of this world; grabs hold \
         points of a system with kind = \"modal_solid\""
    )]
    NotModal {
        /// The control's name.
        name: String,
        /// The index it names.
        system: usize,
    },
    /// The solid refused a grab; `name` is the grab at fault, or says
    /// that the solid refused its grabs together (too many rows) or one
    /// of the scene's own.
    #[error("control `{name}` on systems[{system}]: {source}")]
    Grab {
        /// The grab at fault.
        name: String,
        /// The solid's index.
        system: usize,
        /// Why.
        source: GrabError,
    },
}

impl World {
    /// The runtime controls in force, by name.
    pub fn controls(&self) -> &Controls {
        &self.controls
    }

    /// Replaces the runtime controls with `controls`, all or nothing: each
    /// modal solid holds its scene's grabs and the grabs `controls` name
    /// for it, from the next step.
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
            let modal = self.modal_solids().any(|(m, _)| m == system);
            (!modal).then(|| (grabs[0].0.to_owned(), system))
        }) {
            return Err(ControlError::NotModal { name, system });
        }
        let mut done: Vec<(usize, Vec<Grab>)> = Vec::new();
        let mut refused = None;
        for m in self.systems.iter_mut().filter_map(System::as_modal_mut) {
            let named = wanted.get(&m.index).map_or(&[][..], Vec::as_slice);
            let grabs: Vec<Grab> = named.iter().map(|&(_, g)| g).collect();
            let before = m.extra_grabs().to_vec();
            if let Err(source) = m.set_grabs(&grabs) {
                let name = grab_name(&source, m.scene_grabs.len(), named);
                refused = Some(ControlError::Grab {
                    name,
                    system: m.index,
                    source,
                });
                break;
            }
            done.push((m.index, before));
        }
        if let Some(error) = refused {
            for (index, previous) in done {
                if let Some(m) = self.system_mut(index).and_then(System::as_modal_mut) {
                    // They held before: they hold again.
                    let _ = m.set_grabs(&previous);
                }
            }
            return Err(error);
        }
        self.controls = controls;
        Ok(())
    }
}

/// The name of the grab a solid's error points at: its index counts the
/// scene's grabs first, then the named ones.
fn grab_name(error: &GrabError, scene_grabs: usize, named: &[(&str, Grab)]) -> String {
    let index = match error {
        GrabError::Empty { index }
        | GrabError::NotFinite { index }
        | GrabError::Outside { index, .. }
        | GrabError::Orientation { index } => *index,
        GrabError::TooMany { .. } | GrabError::Modal(_) => {
            return "(the solid's grabs together)".into();
        }
    };
    match index.checked_sub(scene_grabs) {
        Some(k) => named
            .get(k)
            .map_or_else(String::new, |(name, _)| (*name).to_owned()),
        None => format!("(the scene's grabs[{index}])"),
    }
}
