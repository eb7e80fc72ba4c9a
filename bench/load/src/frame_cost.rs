//! The server's CPU per frame, before and after frames were encoded once
//! (issue 31), measured in the same run on the same frame: an engine
//! frame of `n` particles with positions and velocities, as a fluid scene
//! that asks for velocities publishes.
//!
//! Before, every reader of a frame (the zenoh publisher, each latest-frame
//! query, each `GetLatestFrame`) converted the engine frame to its message
//! and encoded it, on a tokio worker thread. Now the compute thread
//! encodes it once ([`meshless_server::EncodedFrame`], the server's own
//! type) and each reader copies or seals the bytes, or decodes them for
//! `GetLatestFrame`. The figures are the median of `reps` timings of each
//! operation, in milliseconds.

use meshless_engine::{FieldData, FieldKind, Frame};
use meshless_proto::seal::Sealer;
use meshless_proto::v1;
use meshless_server::EncodedFrame;
use meshless_wire::frame::frame_to_proto;
use prost::Message;
use std::time::Instant;

/// The session id the frames name.
const SESSION: &str = "load-bench";

/// Medians of one frame size, ms.
#[derive(Debug, Clone, Copy)]
pub struct FrameCost {
    /// Particles per frame.
    pub particles: usize,
    /// Encoded size of one frame, bytes.
    pub frame_bytes: usize,
    /// Before: a publish or latest-frame reply, converted and encoded
    /// (plain).
    pub before_put: f64,
    /// Before: the same, sealed.
    pub before_sealed: f64,
    /// Before: a `GetLatestFrame`, converted.
    pub before_get: f64,
    /// Now, once per frame on the compute thread: converted and encoded.
    pub encode_once: f64,
    /// Now: a publish or latest-frame reply, copied (plain).
    pub after_put: f64,
    /// Now: the same, sealed from the bytes.
    pub after_sealed: f64,
    /// Now: a `GetLatestFrame`, decoded from the bytes.
    pub after_get: f64,
}

/// An engine frame of `particles` particles with positions and
/// velocities.
pub fn engine_frame(particles: usize) -> Frame {
    let field = |kind: FieldKind| FieldData {
        kind,
        components: 3,
        values: (0..particles * 3).map(|i| i as f32 * 1e-3).collect(),
    };
    Frame {
        step: 1,
        time: 0.01,
        substeps: 1,
        substep_dt: 0.01,
        solver_iterations: 0,
        density_error: 0.0,
        capped: false,
        unconverged: 0,
        added: 0,
        particle_count: particles,
        fields: vec![field(FieldKind::Position), field(FieldKind::Velocity)],
        ids: None,
        bodies: Vec::new(),
        surface: None,
        solids: Vec::new(),
        solid_surfaces: Vec::new(),
        crack_surfaces: Vec::new(),
    }
}

/// The median of `reps` timings of `work`, ms.
fn median_ms<R>(reps: usize, mut work: impl FnMut() -> R) -> f64 {
    let mut times: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(work());
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Times every operation on a frame of `particles` particles, `reps`
/// times each.
///
/// # Errors
/// When the random seal key cannot be made, or the encoded frame does not
/// decode (a bug).
pub fn measure(particles: usize, reps: usize) -> anyhow::Result<FrameCost> {
    let frame = engine_frame(particles);
    let sealer = Sealer::generate().map_err(|e| anyhow::anyhow!("seal key: {e}"))?;
    let key = meshless_proto::keys::frames(SESSION);
    let encoded = EncodedFrame::encode(SESSION, &frame);
    anyhow::ensure!(
        encoded.to_proto()? == frame_to_proto(SESSION, &frame),
        "the encoded frame decodes to the frame"
    );
    Ok(FrameCost {
        particles,
        frame_bytes: encoded.bytes().len(),
        before_put: median_ms(reps, || frame_to_proto(SESSION, &frame).encode_to_vec()),
        before_sealed: median_ms(reps, || sealer.seal(&key, &frame_to_proto(SESSION, &frame))),
        before_get: median_ms(reps, || frame_to_proto(SESSION, &frame)),
        encode_once: median_ms(reps, || EncodedFrame::encode(SESSION, &frame)),
        after_put: median_ms(reps, || encoded.bytes().to_vec()),
        after_sealed: median_ms(reps, || sealer.seal_encoded(&key, encoded.bytes())),
        after_get: median_ms(reps, || {
            encoded.to_proto().map(|f: v1::Frame| f.fields.len())
        }),
    })
}
