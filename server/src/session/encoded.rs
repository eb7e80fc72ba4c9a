//! A frame encoded once, on the session's compute thread, as the
//! `meshless.v1.Frame` bytes every reader shares: the zenoh publisher
//! seals (or copies) them per put, the latest-frame queryable answers with
//! them, `GetLatestFrame` decodes them. Before, each of those converted and
//! encoded the engine frame again, on the async runtime's threads: tens of
//! milliseconds of a worker thread per reader at a million particles.

use meshless_engine::Frame;
use meshless_proto::v1;
use meshless_wire::frame::frame_to_proto;
use prost::Message;
use prost::bytes::Bytes;

/// One frame's wire bytes and the step it shows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodedFrame {
    step: u64,
    bytes: Bytes,
}

impl EncodedFrame {
    /// `frame` of session `session_id`, converted and encoded: the CPU
    /// work of a frame, done once.
    pub fn encode(session_id: &str, frame: &Frame) -> Self {
        Self {
            step: frame.step,
            bytes: frame_to_proto(session_id, frame).encode_to_vec().into(),
        }
    }

    /// The step the frame shows.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// The encoded `meshless.v1.Frame`.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The encoded bytes, shared: a reference count, not a copy.
    pub fn to_bytes(&self) -> Bytes {
        self.bytes.clone()
    }

    /// The message back, for `GetLatestFrame`: its fields' data are
    /// slices of these bytes, not copies, and no conversion runs.
    ///
    /// # Errors
    /// A decoding error, which bytes this type encoded never give.
    pub fn to_proto(&self) -> Result<v1::Frame, prost::DecodeError> {
        v1::Frame::decode(self.bytes.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::{BuildOptions, Scene};

    #[test]
    fn the_bytes_are_the_frame_as_the_wire_carries_it() {
        let scene = Scene::from_toml_str(include_str!("../../../tests/fixtures/small_tank.toml"))
            .expect("fixture");
        let frame = scene
            .build(&BuildOptions::default())
            .expect("world")
            .frame();
        let encoded = EncodedFrame::encode("s-1", &frame);
        assert_eq!(encoded.step(), 0);
        let decoded = encoded.to_proto().expect("decodes");
        assert_eq!(decoded, frame_to_proto("s-1", &frame));
        let data = &decoded.fields[0].data;
        let inside = encoded.bytes().as_ptr_range();
        assert!(
            inside.contains(&data.as_ptr()),
            "the positions are a slice of the encoded frame, not a copy"
        );
    }
}
