//! Periodic axes of a box: particles leaving one face re-enter through the
//! opposite one, and pairs interact through the nearest periodic image
//! (the minimum-image convention of molecular dynamics). This stands in
//! for an infinite fluid along those axes: channel flows, Taylor–Green
//! vortices, any bulk flow without walls.

use crate::math::{Real, Vector};

/// The periodic axes of the box `[min, max)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Periodic {
    min: Vector,
    extent: Vector,
    axes: [bool; 3],
}

impl Periodic {
    /// Periodicity of `[min, max)` along `axes`; `None` when no axis is
    /// periodic, so that non-periodic scenes carry nothing.
    pub fn new(min: Vector, max: Vector, axes: [bool; 3]) -> Option<Self> {
        axes.contains(&true).then(|| Self {
            min,
            extent: max - min,
            axes,
        })
    }

    /// Whether `axis` is periodic.
    #[inline]
    pub fn is_periodic(&self, axis: usize) -> bool {
        self.axes[axis]
    }

    /// Brings `x` back into `[min, max)` along the periodic axes.
    #[inline]
    pub fn wrap(&self, x: &mut Vector) {
        for a in 0..3 {
            if self.axes[a] {
                let offset = (x[a] - self.min[a]).rem_euclid(self.extent[a]);
                // `rem_euclid` can round up to the extent itself.
                x[a] = self.min[a] + if offset < self.extent[a] { offset } else { 0.0 };
            }
        }
    }

    /// The shortest periodic image of the separation `d`: along each
    /// periodic axis, `d - L round(d / L)`, so `|d_a| <= L / 2`.
    #[inline]
    pub fn image(&self, mut d: Vector) -> Vector {
        for a in 0..3 {
            if self.axes[a] {
                d[a] -= self.extent[a] * (d[a] / self.extent[a]).round();
            }
        }
        d
    }

    /// The smallest extent of a periodic axis.
    pub fn min_period(&self) -> Real {
        (0..3)
            .filter(|&a| self.axes[a])
            .map(|a| self.extent[a])
            .fold(Real::INFINITY, Real::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_x() -> Periodic {
        Periodic::new(
            Vector::zeros(),
            Vector::new(2.0, 1.0, 1.0),
            [true, false, false],
        )
        .expect("x is periodic")
    }

    #[test]
    fn no_periodic_axis_is_none() {
        assert!(Periodic::new(Vector::zeros(), Vector::repeat(1.0), [false; 3]).is_none());
    }

    #[test]
    fn wrap_moves_only_periodic_axes_into_the_box() {
        let p = unit_x();
        let mut x = Vector::new(-0.25, 1.5, -3.0);
        p.wrap(&mut x);
        assert!((x - Vector::new(1.75, 1.5, -3.0)).norm() < 1e-15);
        let mut x = Vector::new(4.5, 0.0, 0.0);
        p.wrap(&mut x);
        assert!((x.x - 0.5).abs() < 1e-15);
        let mut x = Vector::new(-1e-17, 0.0, 0.0);
        p.wrap(&mut x);
        assert!(x.x >= 0.0 && x.x < 2.0);
    }

    #[test]
    fn image_is_the_shortest_separation() {
        let p = unit_x();
        let d = p.image(Vector::new(1.9, 0.9, 0.0));
        assert!((d - Vector::new(-0.1, 0.9, 0.0)).norm() < 1e-15);
        let d = p.image(Vector::new(-1.2, 0.0, 0.0));
        assert!((d.x - 0.8).abs() < 1e-15);
    }
}
