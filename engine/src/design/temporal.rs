//! Temporal MLS shape functions for keyframed motion design (Adams–Wicke
//! tutorial, Sec. 8.2, Eq. 80–83).
//!
//! A motion is sampled at frames `t_j`; the deformation at time `t` is
//! `u(t) = sum_j phi_j(t) u_j` (Eq. 80), and the velocity and acceleration
//! penalties (Eq. 82, 83) need `phi_j'` and `phi_j''`. With `T >= 3` frames the
//! `phi_j` are 1D MLS shape functions with the complete quadratic basis, so
//! any quadratic motion is reproduced exactly; with two frames they are linear
//! interpolation, as the paper prescribes.
//!
//! # Derivation
//!
//! With weights `w_j(t)`, basis `p(tau) = [1, s, s^2]`, `s = (tau - c) / L`,
//! `p_j = p(t_j)` and moment matrix `M(t) = sum_j w_j p_j p_j^T`, MLS gives
//! `phi_j = w_j gamma^T p_j` with `M gamma = p(t)`. Differentiating
//! `M gamma = p` once and twice:
//! `gamma' = M^-1 (p' - M' gamma)`, `gamma'' = M^-1 (p'' - 2 M' gamma' - M'' gamma)`,
//! where `M' = sum w_j' p_j p_j^T`, `M'' = sum w_j'' p_j p_j^T` (the `p_j` do not
//! move). Then `phi_j' = (w_j' gamma + w_j gamma')^T p_j` and
//! `phi_j'' = (w_j'' gamma + 2 w_j' gamma' + w_j gamma'')^T p_j`.
//! A change of centre `c` or scale `L` is an invertible linear change of the
//! basis, under which MLS shape functions are invariant; so `c` and `L` may be
//! picked afresh at every `t` (we take the weighted mean of the contributing
//! frames and their largest distance from it, which keeps `|s| <= 1` and `M`
//! well conditioned) and held constant while differentiating.
//!
//! The weight `w = (1 - q^2)^3`, `q = |t - t_j| / h_j`, is C2 (its value and
//! first two derivatives vanish at `q = 1`), so `phi_j''` is continuous.

use nalgebra::{Matrix3, Vector3};

use crate::math::Real;

/// Supports are this much wider than the spacing they must span, so that
/// the frames the coverage proof relies on have strictly positive weight.
const SUPPORT_MARGIN: Real = 1.01;
/// Moment matrices worse conditioned than this (Frobenius estimate) are
/// refused: the shape functions would keep fewer than ~4 correct digits.
const MAX_CONDITION: Real = 1e12;

/// Frames at sorted, strictly increasing times with per-frame support radii.
#[derive(Debug, Clone, PartialEq)]
pub struct TemporalBasis {
    times: Vec<Real>,
    supports: Vec<Real>,
}

/// One frame's shape function and its time derivatives at some time `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemporalWeight {
    /// Index `j` of the frame in the basis's times.
    pub frame: usize,
    /// `phi_j(t)`.
    pub value: Real,
    /// `d phi_j / dt`.
    pub d1: Real,
    /// `d^2 phi_j / dt^2`.
    pub d2: Real,
}

/// Why a temporal basis could not be built or evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TemporalError {
    /// Fewer than 2 frame times were given.
    #[error("a motion needs at least 2 frames, got {count}: add keyframes")]
    TooFewFrames {
        /// Frames given.
        count: usize,
    },
    /// A frame time is NaN or infinite.
    #[error("frame {frame} has a non-finite time ({time}): give every frame a finite time")]
    NonFiniteTime {
        /// Index of the offending frame.
        frame: usize,
        /// Its time, s.
        time: Real,
    },
    /// A frame time is not later than the one before it.
    #[error(
        "frame {frame} (t = {time}) does not come after frame {} (t = {previous}): \
         frame times must be strictly increasing", frame - 1
    )]
    NotIncreasing {
        /// Index of the offending frame.
        frame: usize,
        /// Its time, s.
        time: Real,
        /// The time of the frame before it, s.
        previous: Real,
    },
    /// The last time minus the first is not finite.
    #[error("the frame times span [{start}, {end}] overflows: use a smaller time range")]
    SpanOverflow {
        /// First frame time, s.
        start: Real,
        /// Last frame time, s.
        end: Real,
    },
    /// Shape functions were asked for at a time outside the frames' span,
    /// or at NaN.
    #[error("t = {t} lies outside the frames' span [{start}, {end}]: evaluate only inside it")]
    OutOfRange {
        /// The requested time, s.
        t: Real,
        /// First frame time, s.
        start: Real,
        /// Last frame time, s.
        end: Real,
    },
    /// A frame was to be inserted at or beyond the first or last frame
    /// time, or at NaN.
    #[error("cannot insert a frame at t = {t}: it must lie strictly inside ({start}, {end})")]
    InsertOutside {
        /// The requested time, s.
        t: Real,
        /// First frame time, s.
        start: Real,
        /// Last frame time, s.
        end: Real,
    },
    /// A frame was to be inserted at the time of an existing frame.
    #[error("cannot insert a frame at t = {t}: frame {frame} is already there")]
    InsertAtExisting {
        /// The requested time, s.
        t: Real,
        /// Index of the frame already at `t`.
        frame: usize,
    },
    /// The Jacobi-scaled moment matrix `M(t)` is singular or its condition
    /// estimate exceeds `MAX_CONDITION` (1e12).
    #[error(
        "the temporal moment matrix at t = {t} is ill-conditioned (condition ~{condition:e}): \
         the frames near t are too unevenly spaced; insert frames to even out the spacing"
    )]
    IllConditioned {
        /// The time evaluated, s.
        t: Real,
        /// Frobenius condition estimate of the scaled moment matrix.
        condition: Real,
    },
}

impl TemporalBasis {
    /// Validates the frame times and chooses supports
    /// `h_j = 1.01 max(t_{min(j+2,T-1)} - t_j, t_j - t_{max(j-2,0)})`.
    ///
    /// Coverage (the paper's "at least 3 neighbouring frames"): take `T >= 3`
    /// and `t` in `[t_k, t_{k+1}]`. Frame `k`: `|t - t_k| <= t_{k+1} - t_k <=
    /// t_{min(k+2,T-1)} - t_k < h_k`. Frame `k+1`: `|t - t_{k+1}| <= t_{k+1} - t_k
    /// <= t_{k+1} - t_{max(k-1,0)} < h_{k+1}`. Third frame: if `k+2 <= T-1`,
    /// `|t - t_{k+2}| <= t_{k+2} - t_k < h_{k+2}` (its backward term); otherwise
    /// `k = T-2 >= 1` and `|t - t_{k-1}| <= t_{k+1} - t_{k-1} < h_{k-1}` (its
    /// forward term). All inequalities `< h` are strict because the spacings are
    /// positive and the margin exceeds 1, so three distinct frames have `q < 1`,
    /// positive weight, and the quadratic moment matrix is non-singular.
    ///
    /// # Errors
    /// Fewer than 2 frames, a non-finite time, times not strictly increasing,
    /// or a span that overflows.
    pub fn new(times: &[Real]) -> Result<Self, TemporalError> {
        if times.len() < 2 {
            return Err(TemporalError::TooFewFrames { count: times.len() });
        }
        for (frame, &time) in times.iter().enumerate() {
            if !time.is_finite() {
                return Err(TemporalError::NonFiniteTime { frame, time });
            }
            if frame > 0 && time <= times[frame - 1] {
                let previous = times[frame - 1];
                return Err(TemporalError::NotIncreasing {
                    frame,
                    time,
                    previous,
                });
            }
        }
        let last = times.len() - 1;
        let (start, end) = (times[0], times[last]);
        if !(end - start).is_finite() {
            return Err(TemporalError::SpanOverflow { start, end });
        }
        let supports = (0..=last)
            .map(|j| {
                let ahead = times[(j + 2).min(last)] - times[j];
                let behind = times[j] - times[j.saturating_sub(2)];
                SUPPORT_MARGIN * ahead.max(behind)
            })
            .collect();
        Ok(Self {
            times: times.to_vec(),
            supports,
        })
    }

    /// The frame times `t_j`, s, strictly increasing.
    pub fn times(&self) -> &[Real] {
        &self.times
    }

    /// The support radius `h_j` of each frame's weight, s (see [`Self::new`]).
    pub fn supports(&self) -> &[Real] {
        &self.supports
    }

    /// Number of frames (always at least 2, hence no `is_empty`).
    #[allow(clippy::len_without_is_empty)]
    pub fn len(&self) -> usize {
        self.times.len()
    }

    fn span(&self) -> (Real, Real) {
        (self.times[0], self.times[self.times.len() - 1])
    }

    /// Shape functions at `t` (Eq. 80) with first and second time derivatives
    /// (for Eq. 82, 83): one entry per frame with non-zero weight, written to
    /// `out` (cleared first, so callers can reuse it). Scans all frames: `T` is
    /// a handful of keyframes plus adaptively inserted ones.
    ///
    /// # Errors
    /// `t` outside `[t_0, t_{T-1}]` (or NaN), or a moment matrix too
    /// ill-conditioned to trust (only for extremely uneven spacing).
    pub fn shape_functions(
        &self,
        t: Real,
        out: &mut Vec<TemporalWeight>,
    ) -> Result<(), TemporalError> {
        out.clear();
        let (start, end) = self.span();
        if !(t >= start && t <= end) {
            return Err(TemporalError::OutOfRange { t, start, end });
        }
        if self.times.len() == 2 {
            let step = end - start;
            out.push(TemporalWeight {
                frame: 0,
                value: (end - t) / step,
                d1: -1.0 / step,
                d2: 0.0,
            });
            out.push(TemporalWeight {
                frame: 1,
                value: (t - start) / step,
                d1: 1.0 / step,
                d2: 0.0,
            });
            return Ok(());
        }
        // First pass: weights w_j, w_j', w_j'' (stored in `out`, overwritten below).
        for (frame, (&tj, &h)) in self.times.iter().zip(&self.supports).enumerate() {
            let r = (t - tj) / h;
            let u = 1.0 - r * r;
            if u > 0.0 {
                let (value, d1) = (u * u * u, -6.0 * r * u * u / h);
                let d2 = -6.0 * u * (u - 4.0 * r * r) / (h * h);
                out.push(TemporalWeight {
                    frame,
                    value,
                    d1,
                    d2,
                });
            }
        }
        let weight_sum: Real = out.iter().map(|w| w.value).sum();
        let centre = out
            .iter()
            .map(|w| w.value * self.times[w.frame])
            .sum::<Real>()
            / weight_sum;
        let scale = out.iter().fold(0.0, |m: Real, w| {
            m.max((self.times[w.frame] - centre).abs())
        });
        let basis = |tau: Real| {
            let s = (tau - centre) / scale;
            Vector3::new(1.0, s, s * s)
        };
        let (mut m0, mut m1, mut m2) = (Matrix3::zeros(), Matrix3::zeros(), Matrix3::zeros());
        for w in out.iter() {
            let pj = basis(self.times[w.frame]);
            let outer = pj * pj.transpose();
            m0 += w.value * outer;
            m1 += w.d1 * outer;
            m2 += w.d2 * outer;
        }
        // Jacobi scaling before inverting: M^-1 = D (D M D)^-1 D with
        // D = diag(M_ii^-1/2), which evens out rows dominated by tiny weights.
        let jacobi = Matrix3::from_diagonal(&m0.diagonal().map(|d| 1.0 / d.sqrt()));
        let scaled = jacobi * m0 * jacobi;
        let scaled_inverse = scaled.try_inverse().unwrap_or_else(Matrix3::zeros);
        let condition = scaled.norm() * scaled_inverse.norm();
        if !(condition.is_finite() && condition > 0.0 && condition <= MAX_CONDITION) {
            out.clear();
            return Err(TemporalError::IllConditioned { t, condition });
        }
        let inverse = jacobi * scaled_inverse * jacobi;
        let s = (t - centre) / scale;
        let p = Vector3::new(1.0, s, s * s);
        let dp = Vector3::new(0.0, 1.0 / scale, 2.0 * s / scale);
        let d2p = Vector3::new(0.0, 0.0, 2.0 / (scale * scale));
        let g0 = inverse * p;
        let g1 = inverse * (dp - m1 * g0);
        let g2 = inverse * (d2p - 2.0 * (m1 * g1) - m2 * g0);
        for w in out.iter_mut() {
            let pj = basis(self.times[w.frame]);
            let (a0, a1, a2) = (g0.dot(&pj), g1.dot(&pj), g2.dot(&pj));
            let (w0, w1, w2) = (w.value, w.d1, w.d2);
            w.value = w0 * a0;
            w.d1 = w1 * a0 + w0 * a1;
            w.d2 = w2 * a0 + 2.0 * w1 * a1 + w0 * a2;
        }
        Ok(())
    }

    /// A new basis with a frame inserted at `t` (adaptive temporal sampling,
    /// Sec. 8.2), supports recomputed, and the index the new frame got.
    ///
    /// # Errors
    /// `t` not strictly inside the span, or equal to an existing frame time.
    pub fn with_frame(&self, t: Real) -> Result<(Self, usize), TemporalError> {
        let (start, end) = self.span();
        if !(t > start && t < end) {
            return Err(TemporalError::InsertOutside { t, start, end });
        }
        let index = self.times.partition_point(|&x| x < t);
        if self.times.get(index) == Some(&t) {
            return Err(TemporalError::InsertAtExisting { t, frame: index });
        }
        let mut times = self.times.clone();
        times.insert(index, t);
        Ok((Self::new(&times)?, index))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;

    const LAYOUTS: [&[Real]; 3] = [
        &[0.0, 0.7, 2.0],
        &[-1.0, -0.2, 0.5, 2.5],
        &[0.0, 0.3, 0.45, 1.2, 1.5, 2.6, 3.0],
    ];
    /// Gaps of 0.01 next to gaps of 1.0.
    const UNEVEN: &[Real] = &[0.0, 0.01, 1.01, 1.02, 2.02, 3.02, 3.03];

    fn eval(basis: &TemporalBasis, t: Real) -> Vec<TemporalWeight> {
        let mut out = Vec::new();
        basis
            .shape_functions(t, &mut out)
            .expect("t inside the span");
        out
    }

    /// Sample times: a uniform grid over the span, plus every frame time.
    fn samples(times: &[Real], n: usize) -> Vec<Real> {
        let (a, b) = (times[0], times[times.len() - 1]);
        (0..=n)
            .map(|i| a + (b - a) * i as Real / n as Real)
            .chain(times.iter().copied())
            .collect()
    }

    /// Largest error reproducing f = a + b t + c t^2 and its two derivatives
    /// (relative to 1 + |exact|), and of the partition of unity and its
    /// derivatives, over the layout's samples.
    fn worst_reproduction_error(times: &[Real]) -> Real {
        let basis = TemporalBasis::new(times).expect("valid layout");
        let (a, b, c) = (0.7, -1.3, 2.1);
        let f = |t: Real| a + b * t + c * t * t;
        let mut worst: Real = 0.0;
        for t in samples(times, 400) {
            let ws = eval(&basis, t);
            let sum = |g: &dyn Fn(&TemporalWeight) -> Real| ws.iter().map(g).sum::<Real>();
            let fj = |w: &TemporalWeight| f(times[w.frame]);
            let checks = [
                (sum(&|w| w.value), 1.0),
                (sum(&|w| w.d1), 0.0),
                (sum(&|w| w.d2), 0.0),
                (sum(&|w| w.value * fj(w)), f(t)),
                (sum(&|w| w.d1 * fj(w)), b + 2.0 * c * t),
                (sum(&|w| w.d2 * fj(w)), 2.0 * c),
            ];
            for (got, exact) in checks {
                assert!(got.is_finite(), "non-finite sum at t = {t} for {times:?}");
                worst = worst.max((got - exact).abs() / (1.0 + exact.abs()));
            }
        }
        worst
    }

    /// Second-order consistency: quadratics, and hence constants (partition
    /// of unity), are reproduced with their first and second derivatives.
    #[test]
    fn reproduces_quadratics_and_their_derivatives() {
        for times in LAYOUTS {
            let err = worst_reproduction_error(times);
            assert!(err < 1e-9, "T = {}: worst error {err:e}", times.len());
        }
        let err = worst_reproduction_error(UNEVEN);
        assert!(err < 1e-7, "uneven layout: worst error {err:e}");
    }

    /// The analytic phi' and phi'' match central differences of phi and phi'.
    #[test]
    fn derivatives_match_finite_differences() {
        let mut seed = 7;
        for times in LAYOUTS.into_iter().chain([UNEVEN]) {
            let basis = TemporalBasis::new(times).expect("valid layout");
            let (a, b) = (times[0], times[times.len() - 1]);
            let delta = 1e-6 * (b - a);
            let dense = |t: Real| {
                let mut v = vec![(0.0, 0.0); times.len()];
                eval(&basis, t)
                    .iter()
                    .for_each(|w| v[w.frame] = (w.value, w.d1));
                v
            };
            for _ in 0..50 {
                let t = a + 2.0 * delta + (b - a - 4.0 * delta) * uniform(&mut seed);
                let (lo, hi) = (dense(t - delta), dense(t + delta));
                let ws = eval(&basis, t);
                let scale1 = ws.iter().fold(1.0, |m: Real, w| m.max(w.d1.abs()));
                let scale2 = ws.iter().fold(1.0, |m: Real, w| m.max(w.d2.abs()));
                for w in &ws {
                    let fd1 = (hi[w.frame].0 - lo[w.frame].0) / (2.0 * delta);
                    let fd2 = (hi[w.frame].1 - lo[w.frame].1) / (2.0 * delta);
                    let ok =
                        (fd1 - w.d1).abs() < 1e-5 * scale1 && (fd2 - w.d2).abs() < 1e-5 * scale2;
                    assert!(ok, "t = {t}: {w:?} vs differences ({fd1}, {fd2})");
                }
            }
        }
    }

    /// Every time in the span lies strictly inside at least 3 supports (the
    /// doc proof of `new`), including after adaptive insertions.
    #[test]
    fn every_time_is_covered_by_three_frames() {
        let inserted = TemporalBasis::new(UNEVEN).and_then(|b| b.with_frame(0.005));
        let inserted = inserted.expect("insert").0;
        let layouts: Vec<Vec<Real>> = LAYOUTS
            .iter()
            .map(|l| l.to_vec())
            .chain([
                UNEVEN.to_vec(),
                vec![0.0, 1.0, 1.01],
                vec![0.0, 0.01, 1.01],
                inserted.times().to_vec(),
            ])
            .collect();
        for times in &layouts {
            let basis = TemporalBasis::new(times).expect("valid layout");
            for t in samples(times, 20_000) {
                let covering = times
                    .iter()
                    .zip(basis.supports())
                    .filter(|&(&tj, &h)| (t - tj).abs() < h)
                    .count();
                let evaluated = eval(&basis, t).len();
                let ok = covering >= 3 && evaluated >= 3;
                assert!(
                    ok,
                    "t = {t}: {covering} supports, {evaluated} shape functions"
                );
            }
        }
    }

    /// With two frames the paper falls back to linear interpolation.
    #[test]
    fn two_frames_interpolate_linearly() {
        let basis = TemporalBasis::new(&[1.0, 3.0]).expect("valid");
        for t in [1.0, 1.5, 2.0, 3.0] {
            let ws = eval(&basis, t);
            let u = (t - 1.0) / 2.0;
            assert_eq!(ws.len(), 2);
            assert!((ws[0].value - (1.0 - u)).abs() < 1e-15 && (ws[1].value - u).abs() < 1e-15);
            assert!((ws[0].d1 + 0.5).abs() < 1e-15 && (ws[1].d1 - 0.5).abs() < 1e-15);
            assert!(
                ws.iter().all(|w| w.d2 == 0.0),
                "second derivative must vanish at t = {t}"
            );
        }
    }

    /// Bad input is an error whose message says what to change, never a panic.
    #[test]
    fn bad_input_is_reported() {
        let message = |e: TemporalError| e.to_string();
        let err = TemporalBasis::new(&[1.0]).expect_err("one frame");
        assert!(message(err).contains("at least 2 frames"));
        let err = TemporalBasis::new(&[0.0, Real::NAN, 2.0]).expect_err("NaN");
        assert!(
            matches!(err, TemporalError::NonFiniteTime { frame: 1, .. }),
            "{err:?}"
        );
        assert!(message(err).contains("frame 1"));
        let err = TemporalBasis::new(&[0.0, 2.0, 2.0]).expect_err("repeated");
        assert!(message(err).contains("frame 2 (t = 2) does not come after frame 1"));
        assert!(TemporalBasis::new(&[-Real::MAX, Real::MAX]).is_err());
        let basis = TemporalBasis::new(&[0.0, 1.0, 2.0]).expect("valid");
        let mut out = eval(&basis, 1.0);
        for t in [-0.1, 2.1, Real::NAN] {
            let err = basis
                .shape_functions(t, &mut out)
                .expect_err("out of range");
            assert!(
                message(err).contains("outside") && out.is_empty(),
                "t = {t}"
            );
        }
        assert!(
            message(basis.with_frame(1.0).expect_err("existing"))
                .contains("frame 1 is already there")
        );
        for t in [0.0, 2.0, 5.0, Real::NAN] {
            assert!(message(basis.with_frame(t).expect_err("outside")).contains("strictly inside"));
        }
    }

    /// Inserting keeps the other frames in order and reports the new index.
    #[test]
    fn with_frame_inserts_in_order() {
        let basis = TemporalBasis::new(&[0.0, 1.0, 3.0]).expect("valid");
        let (first, i) = basis.with_frame(0.5).expect("inside");
        assert_eq!((first.times(), i), (&[0.0, 0.5, 1.0, 3.0][..], 1));
        let (second, j) = first.with_frame(2.0).expect("inside");
        assert_eq!((second.times(), j), (&[0.0, 0.5, 1.0, 2.0, 3.0][..], 3));
        assert_eq!((second.len(), second.supports().len()), (5, 5));
        assert_eq!(basis.times(), &[0.0, 1.0, 3.0], "the original is unchanged");
    }
}
