//! The SPH colour field on a regular grid of nodes: the Shepard-like sum
//! `phi(x) = sum_j (m_j / rho_j) W(|x - x_j|, h)`, 1 inside the fluid and 0
//! a support radius away from it (the field the tutorial's Section 6.5
//! extracts its surface from).

use crate::approx::Kernel;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Scalar values on the nodes of a regular grid, x fastest.
#[derive(Debug, Clone)]
pub(crate) struct NodeGrid {
    /// Position of node (0, 0, 0).
    pub origin: Vector,
    /// Distance between neighbouring nodes.
    pub cell: Real,
    /// Nodes per axis.
    pub dims: [usize; 3],
    pub values: Vec<f32>,
}

impl NodeGrid {
    pub fn position(&self, i: usize, j: usize, k: usize) -> Vector {
        self.origin + Vector::new(i as Real, j as Real, k as Real) * self.cell
    }
}

/// Node index range `[lo, hi]` whose coordinates `origin + n * cell` lie
/// within `[a, b]`, clamped to `0..count`; `None` when empty.
fn node_range(a: Real, b: Real, origin: Real, cell: Real, count: usize) -> Option<(usize, usize)> {
    let lo = ((a - origin) / cell).ceil().max(0.0);
    let hi = ((b - origin) / cell).floor().min(count as Real - 1.0);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// The colour field of particles at `positions` with volumes `m_j / rho_j`
/// on the nodes `origin + (i, j, k) * cell`, `dims` per axis. Each particle
/// scatters into the nodes within its support only, so empty space costs
/// one zero per node. Runs in parallel over the z-planes of nodes, each
/// plane summing the particles of its slab in the same order whatever the
/// thread count.
pub(crate) fn colour_field(
    positions: &[Vector],
    volumes: &[Real],
    kernel: &Kernel,
    origin: Vector,
    cell: Real,
    dims: [usize; 3],
) -> NodeGrid {
    let h = kernel.support();
    let [nx, ny, nz] = dims;
    let mut order: Vec<usize> = (0..positions.len()).collect();
    order.par_sort_unstable_by(|&a, &b| positions[a].z.total_cmp(&positions[b].z));
    let heights: Vec<Real> = order.iter().map(|&p| positions[p].z).collect();
    let mut values = vec![0.0f32; nx * ny * nz];
    values
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, plane)| {
            let z = origin.z + k as Real * cell;
            let lo = heights.partition_point(|&pz| pz <= z - h);
            let hi = heights.partition_point(|&pz| pz < z + h);
            for &p in &order[lo..hi] {
                let (x, volume) = (positions[p], volumes[p]);
                if !(volume.is_finite() && volume > 0.0) {
                    continue;
                }
                let dz2 = (x.z - z) * (x.z - z);
                let reach = (h * h - dz2).max(0.0).sqrt();
                let Some((j0, j1)) = node_range(x.y - reach, x.y + reach, origin.y, cell, ny)
                else {
                    continue;
                };
                let Some((i0, i1)) = node_range(x.x - reach, x.x + reach, origin.x, cell, nx)
                else {
                    continue;
                };
                for j in j0..=j1 {
                    let dy = origin.y + j as Real * cell - x.y;
                    let row = &mut plane[j * nx..(j + 1) * nx];
                    for (i, value) in row.iter_mut().enumerate().take(i1 + 1).skip(i0) {
                        let dx = origin.x + i as Real * cell - x.x;
                        *value += (volume * kernel.value_sq(dx * dx + dy * dy + dz2)) as f32;
                    }
                }
            }
        });
    NodeGrid {
        origin,
        cell,
        dims,
        values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::KernelKind;

    /// A single particle's field is its kernel times its volume, read back
    /// at every node (the scatter misses no node within the support).
    #[test]
    fn one_particle_gives_its_kernel() {
        let kernel = Kernel::new_3d(KernelKind::CubicSpline, 0.1);
        let x = Vector::new(0.013, -0.021, 0.007);
        let origin = Vector::new(-0.15, -0.15, -0.15);
        let grid = colour_field(&[x], &[0.5], &kernel, origin, 0.01, [31, 31, 31]);
        for k in 0..31 {
            for j in 0..31 {
                for i in 0..31 {
                    let r = (grid.position(i, j, k) - x).norm();
                    let expected = 0.5 * kernel.value(r);
                    let got = f64::from(grid.values[i + 31 * (j + 31 * k)]);
                    assert!(
                        (got - expected).abs() <= 1e-6 * expected.max(1.0),
                        "node ({i}, {j}, {k}) at r = {r}: {got} against {expected}"
                    );
                }
            }
        }
    }
}
