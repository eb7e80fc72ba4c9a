//! Scene -> world: the runtime systems of a validated scene, and only
//! those it names. The scene is data and never imports the world, so
//! [`Scene::build`] lives here; each kind's build is in its adapter
//! (`system/<kind>.rs`).

use super::system::System;
use super::{Clock, Controls, StepInfo, World};
use crate::frame::FieldKind;
use crate::scene::{BuildOptions, Checked, Prepared, Scene, SceneError};
use crate::stats::StageTimer;

impl Scene {
    /// Validates the scene and builds its world: only the systems and
    /// fields the scene names.
    ///
    /// # Errors
    /// See [`Scene::validate`].
    pub fn build(&self, options: &BuildOptions) -> Result<World, SceneError> {
        self.clone().check(options).map(Checked::build)
    }
}

impl Checked {
    /// Builds the world of the checked scene.
    pub fn build(self) -> World {
        World::new(self.scene, self.systems)
    }
}

impl World {
    /// Builds the world of an already validated scene (see [`Scene::build`])
    /// from what its check prepared for each system, in one pass over the
    /// systems.
    fn new(scene: Scene, prepared: Vec<Prepared>) -> Self {
        let systems = System::build_all(&scene, prepared);
        // Positions first; ids, when named, right after them.
        let mut frame_fields = vec![FieldKind::Position];
        if scene.output.fields.contains(&FieldKind::Id) {
            frame_fields.push(FieldKind::Id);
        }
        for &kind in &scene.output.fields {
            if !frame_fields.contains(&kind) {
                frame_fields.push(kind);
            }
        }
        Self {
            scene,
            clock: Clock::default(),
            last_step: StepInfo::default(),
            timer: StageTimer::default(),
            frame_fields,
            systems,
            controls: Controls::default(),
        }
    }
}
