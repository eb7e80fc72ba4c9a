//! # meshless-load
//!
//! The load bench of the service (`cargo bench -p meshless-load`), in
//! parts that print their tables in turn (`cargo bench -p meshless-load
//! -- NAME...` runs only the parts named):
//!
//! - [`rpc`]: `GetSession` and `Step(1)` over real gRPC on loopback,
//!   sequential, from concurrent callers, and at a fixed arrival rate
//!   (the goal: p99 under 1 ms for `GetSession` at 5,000 calls a
//!   second);
//! - [`frames`]: frames of 10k, 100k and 1M particles delivered over zenoh
//!   to a subscriber that unpacks them (goal: 1M-particle frames at 60 a
//!   second);
//! - [`slow_subscriber`]: a session's steps per second with and without a
//!   subscriber that cannot keep up, as a ratio (goal: at least 0.98);
//! - [`frame_cost`]: what a frame of 100k and 1M particles costs the
//!   server's async runtime per reader (publisher, latest-frame query,
//!   `GetLatestFrame`), converted and encoded per reader as before issue
//!   31 and encoded once on the compute thread as now, in the same run;
//! - [`viewers`]: one session of 100k particles stepping with nobody
//!   watching, then with 20 browser viewers polling `NextFrame` over
//!   gRPC-web on the viewer's listener, in alternating arms: steps per
//!   second and their ratio, frames each viewer got per second, and the
//!   process's resident memory.
//!
//! The server is the real one, started in this process on its own tokio
//! runtime (`meshless_server::start`) and reached over TCP, so the bench
//! needs no binary built beforehand. Nothing here asserts a figure.

pub mod frame_cost;
pub mod frames;
pub mod rpc;
pub mod slow_subscriber;
pub mod viewers;
