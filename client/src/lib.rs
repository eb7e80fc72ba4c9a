//! # meshless-client
//!
//! A thin async client for meshless: [`Client`] drives sessions over gRPC;
//! [`ZenohLink`] subscribes to their frames and status over zenoh and
//! decodes frames into [`FrameView`]s of plain `f32` arrays.
//!
//! ```no_run
//! # async fn demo() -> Result<(), meshless_client::ClientError> {
//! use meshless_client::{Client, ZenohLink};
//! let client = Client::connect("http://127.0.0.1:50051").await?;
//! let info = client.server_info().await?;
//! let session = client
//!     .create_session_toml(&std::fs::read_to_string("scenes/dam_break.toml").unwrap_or_default())
//!     .await?;
//! let link = ZenohLink::connect(&info.zenoh_locators).await?;
//! let frames = link.frames(&session).await?;
//! client.step(&session.id, 10).await?;
//! let frame = frames.recv().await?;
//! println!("step {} with {} particles", frame.step, frame.particle_count);
//! # Ok(()) }
//! ```
//!
//! The library depends on the protocol alone, neither the engine nor the
//! server, and has no features to turn on. The `meshless` command line is
//! the `meshless-cli` crate.

mod client;
mod design;
mod error;
mod frame;
mod link;
mod route;
mod scene_file;

pub use client::{Client, Identity, Tls};
pub use design::{Design, DesignKind, OptimizeEvent};
pub use error::ClientError;
pub use frame::{FieldView, FrameView, SolidSurfaceView, SurfaceView};
pub use link::{DropReason, Dropped, Frames, Statuses, Watched, ZenohLink};
pub use meshless_proto::v1;
pub use route::{Route, server_of};
pub use scene_file::{inline_meshes, read_scene_file};
