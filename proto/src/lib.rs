//! The `meshless.v1` wire protocol: generated message types, the
//! `Simulation` gRPC client and server stubs, and the zenoh key expressions
//! that carry frames and status, and the sealing of what is put on them.
//!
//! The `.proto` files live in `proto/meshless/v1/`, laid out so that Python
//! code generated with `grpc_tools.protoc -I proto` imports as `meshless.v1`.

/// Generated types and stubs of package `meshless.v1`.
///
/// prost turns the `.proto` comments into doc comments (protox keeps the
/// source info), so every message, field, enum value and oneof is
/// documented there and `missing_docs` stays on: an uncommented addition
/// to a `.proto` file fails the lint. tonic's client and server modules
/// allow `missing_docs` themselves; their methods carry the `rpc` comments.
pub mod v1 {
    #![allow(clippy::all, missing_debug_implementations)]
    tonic::include_proto!("meshless.v1");
}

pub mod keys;
pub mod seal;
pub mod snapshot;

/// Encoded `FileDescriptorSet` of all meshless protos, for gRPC reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/meshless_descriptor.bin"));
