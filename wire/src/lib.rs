//! # meshless-wire
//!
//! The one place where the `meshless.v1` protocol ([`meshless_proto`]) and
//! the engine ([`meshless_engine`]) meet, both directions, one module per
//! proto file: [`scene`] (`scene.proto`, a file per system kind inside),
//! [`frame`] (`frame.proto`) and
//! [`design`] (`design.proto`). `simulation.proto` holds only the
//! service's own messages (sessions, status, server info), which the
//! server builds itself.
//!
//! Messages are destructured exhaustively, so a new proto field breaks the
//! build here until it is handled; every enum crosses through one table
//! ([`enums`]) that gives both conversions, its names and the "use a, b or
//! c" text of its errors. A message that does not convert is a
//! [`WireError`] naming the field's path in the message.

#![warn(clippy::wildcard_enum_match_arm)]

pub mod design;
pub mod enums;
mod error;
pub mod frame;
pub mod scene;
pub mod snapshot;

pub use enums::WireEnum;
pub use error::WireError;
