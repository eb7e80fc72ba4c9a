//! Designs as the client sees them: the design particles' rest positions
//! and their displacements per frame, decoded from the flat wire arrays
//! with every length checked.

use crate::ClientError;
use meshless_proto::v1;

/// Which problem a design solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DesignKind {
    /// A deformed shape: one frame, at time 0.
    Shape,
    /// A motion: displacements at a series of frame times.
    Motion,
}

/// A solved design (`DesignResult`).
#[derive(Debug, Clone, PartialEq)]
pub struct Design {
    /// The session the design was solved in.
    pub session_id: String,
    /// The scene system designed.
    pub system: usize,
    /// Shape or motion.
    pub kind: DesignKind,
    /// Iterations, energies per term, convergence, frames.
    pub info: v1::DesignInfo,
    /// Rest position of each design particle, m.
    pub rest_positions: Vec<[f64; 3]>,
    /// Frame times, s (one, 0, for a shape).
    pub times: Vec<f64>,
    /// Per frame, the displacement of each design particle, m.
    pub displacements: Vec<Vec<[f64; 3]>>,
}

/// One event of an optimisation stream.
#[derive(Debug, Clone, PartialEq)]
pub enum OptimizeEvent {
    /// A report after one solver iteration: energies per term, gradient
    /// norm, frames so far.
    Progress(v1::DesignProgress),
    /// The last event of a successful optimisation.
    Done(Design),
}

fn triples(values: &[f64]) -> Vec<[f64; 3]> {
    values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

impl Design {
    /// Decodes a `DesignResult`.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when the arrays do not agree in length or
    /// a field is missing.
    pub fn from_proto(result: v1::DesignResult) -> Result<Self, ClientError> {
        let v1::DesignResult {
            session_id,
            system,
            kind,
            info,
            rest_positions,
            times,
            displacements,
        } = result;
        let bad = |m: String| Err(ClientError::Decode(format!("design: {m}")));
        let kind = match v1::DesignKind::try_from(kind) {
            Ok(v1::DesignKind::Shape) => DesignKind::Shape,
            Ok(v1::DesignKind::Motion) => DesignKind::Motion,
            Ok(v1::DesignKind::Unspecified) | Err(_) => return bad(format!("unknown kind {kind}")),
        };
        let Some(info) = info else {
            return bad("no info".into());
        };
        if rest_positions.len() % 3 != 0 {
            return bad(format!(
                "{} rest coordinates are not whole points",
                rest_positions.len()
            ));
        }
        if times.is_empty() {
            return bad("no frame times".into());
        }
        let per_frame = rest_positions.len();
        if displacements.len() != per_frame * times.len() {
            return bad(format!(
                "{} displacement values for {} frames of {} particles",
                displacements.len(),
                times.len(),
                per_frame / 3
            ));
        }
        let frames = if per_frame == 0 {
            vec![Vec::new(); times.len()]
        } else {
            displacements.chunks_exact(per_frame).map(triples).collect()
        };
        Ok(Self {
            session_id,
            system: system as usize,
            kind,
            info,
            rest_positions: triples(&rest_positions),
            times,
            displacements: frames,
        })
    }

    /// The design particles' positions at frame `frame`.
    pub fn positions(&self, frame: usize) -> Option<Vec<[f64; 3]>> {
        let u = self.displacements.get(frame)?;
        Some(
            self.rest_positions
                .iter()
                .zip(u)
                .map(|(x, u)| [x[0] + u[0], x[1] + u[1], x[2] + u[2]])
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(rest: usize, times: usize, values: usize) -> v1::DesignResult {
        v1::DesignResult {
            session_id: "s".into(),
            system: 0,
            kind: v1::DesignKind::Motion as i32,
            info: Some(v1::DesignInfo::default()),
            rest_positions: vec![1.0; rest],
            times: vec![0.0; times],
            displacements: vec![0.5; values],
        }
    }

    /// Lengths that agree decode into frames of points; any mismatch is a
    /// decode error rather than a short or shifted frame.
    #[test]
    fn design_lengths_are_checked() {
        let design = Design::from_proto(result(6, 2, 12)).expect("consistent lengths");
        assert_eq!(design.displacements.len(), 2);
        assert_eq!(design.positions(1), Some(vec![[1.5; 3]; 2]));
        for (rest, times, values) in [(5, 1, 5), (6, 2, 11), (6, 0, 0)] {
            let error = Design::from_proto(result(rest, times, values));
            assert!(
                matches!(error, Err(ClientError::Decode(_))),
                "({rest}, {times}, {values}) must not decode: {error:?}"
            );
        }
    }
}
