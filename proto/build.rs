//! Compiles `meshless/v1/*.proto` with protox (no system `protoc`) and
//! generates prost types and tonic stubs into `OUT_DIR`. The encoded file
//! descriptor set is kept for gRPC reflection.

use std::path::PathBuf;

use prost::Message;

const PROTOS: &[&str] = &[
    "meshless/v1/scene.proto",
    "meshless/v1/frame.proto",
    "meshless/v1/design.proto",
    "meshless/v1/simulation.proto",
    "meshless/v1/snapshot.proto",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for proto in PROTOS {
        println!("cargo:rerun-if-changed={proto}");
    }
    let descriptors = protox::compile(PROTOS, ["."])?;
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out_dir.join("meshless_descriptor.bin"),
        descriptors.encode_to_vec(),
    )?;
    tonic_prost_build::configure()
        // A frame's field data as `Bytes`: a frame decoded from a `Bytes`
        // buffer (the server's encoded latest frame) shares it instead of
        // copying tens of megabytes.
        .bytes(".meshless.v1.FieldData.data")
        // NextFrame answers with the encoded frame itself: a clone of the
        // session's buffer, not a copy.
        .bytes(".meshless.v1.NextFrameResponse.frame")
        .build_client(true)
        .build_server(true)
        .compile_fds(descriptors)?;
    Ok(())
}
