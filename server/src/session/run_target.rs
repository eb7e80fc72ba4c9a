//! What a run steps towards: its end time and pacing, checked as `Run`
//! and a restored snapshot give them. A leaf of the session folder, so
//! that the worker and the snapshot both use it without importing each
//! other.

use crate::error::ServiceError;

/// What a run steps towards.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunTarget {
    /// Simulated time to stop at; `None` runs until paused.
    pub until: Option<f64>,
    /// Simulated seconds per wall-clock second; `None` is unpaced.
    pub realtime_factor: Option<f64>,
}

/// Real-time factors a paced run accepts. Outside, pacing means nothing a
/// user can watch: a millionth of real time is 11 days per simulated
/// second, and above a million times the run is unpaced in all but name.
const REALTIME_FACTORS: std::ops::RangeInclusive<f64> = 1e-6..=1e6;

impl RunTarget {
    /// A run's end time as `Run` accepts it; a restored run target passes
    /// the same check, since a snapshot is input like a request.
    ///
    /// # Errors
    /// [`ServiceError::InvalidArgument`] for a time that is not finite
    /// and positive.
    pub fn check_until(time: f64) -> Result<f64, ServiceError> {
        if time.is_finite() && time > 0.0 {
            Ok(time)
        } else {
            Err(ServiceError::invalid(
                "until_time",
                format!("must be a finite time > 0 s, got {time}"),
            ))
        }
    }

    /// A run's pacing as `Run` accepts it: 0 or unset is unpaced.
    ///
    /// # Errors
    /// [`ServiceError::InvalidArgument`] for a factor outside
    /// [`REALTIME_FACTORS`] (negative, NaN, vanishing or huge).
    pub fn check_realtime_factor(factor: Option<f64>) -> Result<Option<f64>, ServiceError> {
        match factor {
            Some(0.0) | None => Ok(None),
            Some(f) if REALTIME_FACTORS.contains(&f) => Ok(Some(f)),
            Some(f) => Err(ServiceError::invalid(
                "realtime_factor",
                format!(
                    "must be 0 (as fast as possible) or in [{:e}, {:e}] simulated seconds per \
                     second, got {}",
                    REALTIME_FACTORS.start(),
                    REALTIME_FACTORS.end(),
                    meshless_engine::math::Brief(f)
                ),
            )),
        }
    }
}
