//! The systems a world steps: one adapter per kind behind the
//! [`Simulated`] trait (`simulated.rs`), the [`System`] enum that holds
//! them and dispatches to the trait, and the one pass that builds each
//! kind from what its scene check prepared.
//!
//! Adding a kind of system: its spec and check in `scene/<kind>.rs`, its
//! adapter in `world/system/<kind>.rs` (a struct implementing
//! [`Simulated`] and a `build` function), a variant here with its arms
//! in [`System::simulated`], [`System::simulated_mut`] and
//! [`System::build`], and its [`crate::world::SystemState`] variant.

// Dispatch over systems and frame fields must name every variant: a new
// kind or field that some arm forgets is a compile-time warning, not a
// silently empty field.
#![warn(clippy::wildcard_enum_match_arm)]

pub(crate) mod fluid;
pub(crate) mod modal;
pub(crate) mod shell;
pub(crate) mod simulated;
pub(crate) mod solid;

use crate::geometry::Shape;
use crate::scene::{MotionKind, Prepared, RigidBodySpec, Scene, SystemSpec, body_pose};
use crate::solid::Obstacle;
use fluid::FluidEntry;
use modal::ModalEntry;
use shell::ShellEntry;
pub use simulated::{ChangeError, InsertError, RemoveError};
pub(crate) use simulated::{GrabRefusal, Simulated, StepEnv};
use solid::SolidEntry;

/// A system of the world (each boxed: their sizes differ by kilobytes).
#[derive(Debug, Clone)]
pub(crate) enum System {
    /// The scene's fluid, with its rigid bodies.
    Fluid(Box<FluidEntry>),
    /// An elastic solid.
    Solid(Box<SolidEntry>),
    /// A modal EFG solid.
    Modal(Box<ModalEntry>),
    /// A thin shell.
    Shell(Box<ShellEntry>),
}

impl System {
    /// The system behind the trait the world steps it through.
    pub(crate) fn simulated(&self) -> &dyn Simulated {
        match self {
            Self::Fluid(fluid) => fluid.as_ref(),
            Self::Solid(solid) => solid.as_ref(),
            Self::Modal(modal) => modal.as_ref(),
            Self::Shell(shell) => shell.as_ref(),
        }
    }

    /// [`Self::simulated`], to step or change it.
    pub(crate) fn simulated_mut(&mut self) -> &mut dyn Simulated {
        match self {
            Self::Fluid(fluid) => fluid.as_mut(),
            Self::Solid(solid) => solid.as_mut(),
            Self::Modal(modal) => modal.as_mut(),
            Self::Shell(shell) => shell.as_mut(),
        }
    }

    /// The fluid, if this is one.
    pub(crate) fn as_fluid(&self) -> Option<&FluidEntry> {
        match self {
            Self::Fluid(fluid) => Some(fluid),
            Self::Solid(_) | Self::Modal(_) | Self::Shell(_) => None,
        }
    }

    /// [`Self::as_fluid`], to change it.
    pub(crate) fn as_fluid_mut(&mut self) -> Option<&mut FluidEntry> {
        match self {
            Self::Fluid(fluid) => Some(fluid),
            Self::Solid(_) | Self::Modal(_) | Self::Shell(_) => None,
        }
    }

    /// The elastic solid, if this is one.
    pub(crate) fn as_solid(&self) -> Option<&SolidEntry> {
        match self {
            Self::Solid(solid) => Some(solid),
            Self::Fluid(_) | Self::Modal(_) | Self::Shell(_) => None,
        }
    }

    /// [`Self::as_solid`], to change it.
    pub(crate) fn as_solid_mut(&mut self) -> Option<&mut SolidEntry> {
        match self {
            Self::Solid(solid) => Some(solid),
            Self::Fluid(_) | Self::Modal(_) | Self::Shell(_) => None,
        }
    }

    /// The modal solid, if this is one.
    pub(crate) fn as_modal(&self) -> Option<&ModalEntry> {
        match self {
            Self::Modal(modal) => Some(modal),
            Self::Fluid(_) | Self::Solid(_) | Self::Shell(_) => None,
        }
    }

    /// The shell, if this is one.
    pub(crate) fn as_shell(&self) -> Option<&ShellEntry> {
        match self {
            Self::Shell(shell) => Some(shell),
            Self::Fluid(_) | Self::Solid(_) | Self::Modal(_) => None,
        }
    }

    /// The running systems of a checked scene, from what its check
    /// prepared for each (one entry per system of the scene, of the
    /// system's kind), in step order: the fluid first, then the solids in
    /// scene order. Rigid bodies are the fluid's boundaries and the
    /// solids' static obstacles, not systems of their own.
    pub(crate) fn build_all(scene: &Scene, mut prepared: Vec<Prepared>) -> Vec<System> {
        let Bodies {
            in_fluid,
            obstacles,
        } = Bodies::take(scene, &mut prepared);
        // One fluid at most (checked), which takes the bodies.
        let mut in_fluid = Some(in_fluid);
        let mut systems: Vec<System> = scene
            .systems
            .iter()
            .zip(prepared)
            .enumerate()
            .filter_map(|(index, (spec, prepared))| match (spec, prepared) {
                (SystemSpec::Fluid(spec), Prepared::Nothing) => Some(Self::Fluid(Box::new(
                    fluid::build(scene, index, spec, in_fluid.take().unwrap_or_default()),
                ))),
                (SystemSpec::Solid(spec), Prepared::Solid(sampled)) => Some(Self::Solid(Box::new(
                    solid::build(scene, index, spec, sampled, &obstacles),
                ))),
                (SystemSpec::ModalSolid(spec), Prepared::Modal(solid)) => {
                    Some(Self::Modal(Box::new(modal::build(index, spec, *solid))))
                }
                (SystemSpec::Shell(_), Prepared::Shell(shell)) => {
                    Some(Self::Shell(Box::new(shell::build(index, *shell))))
                }
                (SystemSpec::RigidBody(_), _) => None,
                // `Scene::check` prepares each system as its kind.
                (
                    SystemSpec::Fluid(_)
                    | SystemSpec::Solid(_)
                    | SystemSpec::ModalSolid(_)
                    | SystemSpec::Shell(_),
                    _,
                ) => unreachable!("systems[{index}] was prepared as another kind"),
            })
            .collect();
        // Stable: the solids keep scene order behind the fluid.
        systems.sort_by_key(|s| s.as_fluid().is_none());
        systems
    }
}

/// The scene's rigid bodies as the systems meet them.
struct Bodies<'a> {
    /// Every body with its system index, spec and shape, for the fluid.
    in_fluid: Vec<(usize, &'a RigidBodySpec, Shape)>,
    /// The static bodies, which the solids collide with.
    obstacles: Vec<Obstacle>,
}

impl<'a> Bodies<'a> {
    /// Takes the bodies' shapes out of `prepared`.
    fn take(scene: &'a Scene, prepared: &mut [Prepared]) -> Self {
        let dim = scene.dimension;
        let mut bodies = Self {
            in_fluid: Vec::new(),
            obstacles: Vec::new(),
        };
        for (index, (spec, prepared)) in scene.systems.iter().zip(prepared).enumerate() {
            let SystemSpec::RigidBody(body) = spec else {
                continue;
            };
            let Prepared::Body(shape) = std::mem::take(prepared) else {
                continue;
            };
            if body.motion == MotionKind::Static {
                let (position, orientation) = body_pose(body, &shape, dim);
                bodies.obstacles.push(Obstacle {
                    shape: shape.clone(),
                    position,
                    orientation,
                });
            }
            bodies.in_fluid.push((index, body, shape));
        }
        bodies
    }
}
