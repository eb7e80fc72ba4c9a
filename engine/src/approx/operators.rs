//! SPH approximations of a field and of its derivatives from particle
//! samples (Adams–Wicke tutorial, Section 2.2 and Table 1).
//!
//! Every operator is a sum over the neighbours `j` of particle `i`, with
//! `x_ij = x_i - x_j`, `W_ij = W(|x_ij|)`, `grad W_ij` the gradient of the
//! kernel with respect to `x_i` ([`Kernel::gradient`] of `x_ij`) and the
//! particle volume `V_j = m_j / rho_j`:
//!
//! | operator | form | sum | tutorial |
//! |---|---|---|---|
//! | value | | `sum_j V_j f_j W_ij` | Eq. 3 |
//! | gradient | plain | `sum_j V_j f_j grad W_ij` | Eq. 9 |
//! | gradient | corrected | `sum_j V_j (f_j - f_i) grad W_ij` | Eq. 13 |
//! | gradient | density-weighted | `1/rho_i sum_j m_j (f_j - f_i) grad W_ij` | Eq. 17 |
//! | gradient | symmetric | `rho_i sum_j m_j (f_i/rho_i^2 + f_j/rho_j^2) grad W_ij` | Eq. 19 |
//! | divergence | plain | `sum_j V_j f_j . grad W_ij` | Eq. 12 |
//! | divergence | corrected | `sum_j V_j (f_j - f_i) . grad W_ij` | Eq. 14 |
//! | Laplacian | plain | `sum_j V_j f_j Lap W_ij` | Eq. 11 |
//! | Laplacian | corrected | `sum_j V_j (f_j - f_i) Lap W_ij` | Eq. 15 |
//! | Laplacian | Brookshaw | `2 sum_j V_j (f_i - f_j) (x_ij . grad W_ij) / (x_ij^2 + 0.01 h^2)` | Brookshaw 1985 |
//!
//! `Lap W` is the full radial Laplacian `w'' + (d - 1) w' / r` of
//! [`Kernel::laplacian`], not the `w''` of the tutorial's flattened Eq. 11.
//!
//! Signs: the plain forms differentiate the interpolant
//! `<f>(x) = sum_j V_j f_j W(x - x_j)` at `x = x_i`, so the kernel gradient
//! is taken at `+x_ij`; the corrected forms subtract `f_i` times the
//! approximation of the derivative of the constant 1. With `grad W_ij`
//! pointing from `x_j` towards `x_i` times `w' < 0`, Brookshaw's
//! `x_ij . grad W_ij = |x_ij| w'` is negative and the factor `f_i - f_j`
//! (not `f_j - f_i`) makes the Laplacian of `|x|^2` come out `+2d`.
//!
//! Accuracy, as the tests measure it on interior particles: only the forms
//! that subtract `f_i` (corrected, density-weighted, Brookshaw) are exact
//! for a constant field on a disordered particle set; the plain and
//! symmetric gradients, the plain divergence and above all the plain
//! Laplacian carry an error proportional to the field's magnitude. The
//! symmetric gradient is the one to use for forces (its pair terms are
//! antisymmetric, so momentum is conserved), not for measuring a gradient.
//!
//! All operators gather: one parallel (rayon) work item per particle reads
//! its neighbour list and writes only its own output slot, so results do
//! not depend on the thread count and nothing is allocated.

use super::Kernel;
use crate::math::{Real, Vector};
use crate::neighbors::NeighborList;
use rayon::prelude::*;

/// Brookshaw's regularisation of `1 / |x_ij|^2`: `eta^2 = 0.01 h^2`, with
/// `h` the kernel's support radius.
const BROOKSHAW_ETA2: Real = 0.01;

/// The particles that sample a field: positions, masses and densities
/// (one entry per particle), which give the volumes `V_j = m_j / rho_j`.
#[derive(Debug, Clone, Copy)]
pub struct Samples<'a> {
    /// `x_j`, in the scene's length unit (m).
    pub positions: &'a [Vector],
    /// `m_j` (kg); with [`Self::densities`] they give the volumes `V_j`.
    pub masses: &'a [Real],
    /// `rho_j`, usually the density sum `sum_k m_k W_jk`; must be positive.
    pub densities: &'a [Real],
}

impl Samples<'_> {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether there are no particles.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// `V_j = m_j / rho_j`.
    #[inline]
    fn volume(&self, j: usize) -> Real {
        self.masses[j] / self.densities[j]
    }

    /// Checks that all slices describe the same particles.
    #[track_caller]
    fn check(&self, neighbors: &NeighborList, field: usize, out: usize) {
        let n = self.positions.len();
        assert_eq!(self.masses.len(), n, "one mass per position");
        assert_eq!(self.densities.len(), n, "one density per position");
        assert_eq!(neighbors.len(), n, "neighbour lists for these positions");
        assert_eq!(field, n, "one field value per particle");
        assert_eq!(out, n, "one output per particle");
    }
}

/// Which SPH approximation of the gradient of a scalar field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GradientForm {
    /// Eq. 9, `sum_j V_j f_j grad W_ij`: the derivative of the interpolant.
    /// Not zero for a constant field on a disordered particle set.
    Plain,
    /// Eq. 13, `sum_j V_j (f_j - f_i) grad W_ij`: exact for constants.
    Corrected,
    /// Eq. 17, `1/rho_i sum_j m_j (f_j - f_i) grad W_ij`: exact for
    /// constants, needs the density of `i` only.
    DensityWeighted,
    /// Eq. 19, `rho_i sum_j m_j (f_i/rho_i^2 + f_j/rho_j^2) grad W_ij`:
    /// antisymmetric pair terms (momentum-conserving forces), not exact for
    /// constants.
    Symmetric,
}

impl GradientForm {
    /// Every form, in declaration order, for tests that compare them.
    pub const ALL: [GradientForm; 4] = [
        GradientForm::Plain,
        GradientForm::Corrected,
        GradientForm::DensityWeighted,
        GradientForm::Symmetric,
    ];
}

/// Which SPH approximation of the divergence of a vector field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DivergenceForm {
    /// Eq. 12, `sum_j V_j f_j . grad W_ij`.
    Plain,
    /// Eq. 14, `sum_j V_j (f_j - f_i) . grad W_ij`: exact for constants.
    Corrected,
}

impl DivergenceForm {
    /// Every form, in declaration order, for tests that compare them.
    pub const ALL: [DivergenceForm; 2] = [DivergenceForm::Plain, DivergenceForm::Corrected];
}

/// Which SPH approximation of the Laplacian of a scalar field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LaplacianForm {
    /// Eq. 11, `sum_j V_j f_j Lap W_ij`, self-pair included (`d w''(0)`
    /// for kernels smooth at the origin; spiky and viscosity, whose
    /// Laplacian is singular there, contribute 0 and should not be used).
    /// Very sensitive to particle disorder.
    Plain,
    /// Eq. 15, `sum_j V_j (f_j - f_i) Lap W_ij`: exact for constants.
    Corrected,
    /// Brookshaw (1985), `2 sum_j V_j (f_i - f_j) (x_ij . grad W_ij) /
    /// (|x_ij|^2 + 0.01 h^2)`: needs only the first derivative of the
    /// kernel, exact for constants, the standard stable form.
    Brookshaw,
}

impl LaplacianForm {
    /// Every form, in declaration order, for tests that compare them.
    pub const ALL: [LaplacianForm; 3] = [
        LaplacianForm::Plain,
        LaplacianForm::Corrected,
        LaplacianForm::Brookshaw,
    ];
}

/// The SPH value of a scalar field (Eq. 3):
/// `out_i = sum_j V_j f_j W_ij`.
///
/// With the viscosity kernel the self-pair is infinite: use it for
/// Laplacians only. Runs in parallel, one gather per particle, allocation
/// free.
///
/// # Panics
/// When `f`, `out`, the neighbour lists, masses or densities do not have
/// one entry per position (a programming error).
pub fn value(
    s: &Samples<'_>,
    neighbors: &NeighborList,
    kernel: &Kernel,
    f: &[Real],
    out: &mut [Real],
) {
    s.check(neighbors, f.len(), out.len());
    let x = s.positions;
    out.par_iter_mut().enumerate().for_each(|(i, out)| {
        let xi = x[i];
        *out = neighbors
            .of(i)
            .iter()
            .map(|&j| {
                let j = j as usize;
                s.volume(j) * f[j] * kernel.value_sq((xi - x[j]).norm_squared())
            })
            .sum();
    });
}

/// The SPH gradient of a scalar field in one of the forms of
/// [`GradientForm`] (Eq. 9, 13, 17, 19).
///
/// Runs in parallel, one gather per particle, allocation free.
///
/// # Panics
/// When `f`, `out`, the neighbour lists, masses or densities do not have
/// one entry per position (a programming error).
pub fn gradient(
    s: &Samples<'_>,
    neighbors: &NeighborList,
    kernel: &Kernel,
    form: GradientForm,
    f: &[Real],
    out: &mut [Vector],
) {
    s.check(neighbors, f.len(), out.len());
    let (x, m, rho) = (s.positions, s.masses, s.densities);
    out.par_iter_mut().enumerate().for_each(|(i, out)| {
        let (xi, fi, rho_i) = (x[i], f[i], rho[i]);
        let fi_rho2 = fi / (rho_i * rho_i);
        let mut sum = Vector::zeros();
        for &j in neighbors.of(i) {
            let j = j as usize;
            let xij = xi - x[j];
            let weight = match form {
                GradientForm::Plain => s.volume(j) * f[j],
                GradientForm::Corrected => s.volume(j) * (f[j] - fi),
                GradientForm::DensityWeighted => m[j] * (f[j] - fi),
                GradientForm::Symmetric => m[j] * (fi_rho2 + f[j] / (rho[j] * rho[j])),
            };
            // The self-pair's gradient is zero.
            sum += kernel.gradient(&xij, xij.norm()) * weight;
        }
        *out = match form {
            GradientForm::Plain | GradientForm::Corrected => sum,
            GradientForm::DensityWeighted => sum / rho_i,
            GradientForm::Symmetric => sum * rho_i,
        };
    });
}

/// The SPH divergence of a vector field in one of the forms of
/// [`DivergenceForm`] (Eq. 12, 14).
///
/// Runs in parallel, one gather per particle, allocation free.
///
/// # Panics
/// When `f`, `out`, the neighbour lists, masses or densities do not have
/// one entry per position (a programming error).
pub fn divergence(
    s: &Samples<'_>,
    neighbors: &NeighborList,
    kernel: &Kernel,
    form: DivergenceForm,
    f: &[Vector],
    out: &mut [Real],
) {
    s.check(neighbors, f.len(), out.len());
    let x = s.positions;
    out.par_iter_mut().enumerate().for_each(|(i, out)| {
        let (xi, fi) = (x[i], f[i]);
        *out = neighbors
            .of(i)
            .iter()
            .map(|&j| {
                let j = j as usize;
                let xij = xi - x[j];
                let fj = match form {
                    DivergenceForm::Plain => f[j],
                    DivergenceForm::Corrected => f[j] - fi,
                };
                s.volume(j) * fj.dot(&kernel.gradient(&xij, xij.norm()))
            })
            .sum();
    });
}

/// The SPH Laplacian of a scalar field in one of the forms of
/// [`LaplacianForm`] (Eq. 11, 15 and Brookshaw's).
///
/// Runs in parallel, one gather per particle, allocation free.
///
/// # Panics
/// When `f`, `out`, the neighbour lists, masses or densities do not have
/// one entry per position (a programming error).
pub fn laplacian(
    s: &Samples<'_>,
    neighbors: &NeighborList,
    kernel: &Kernel,
    form: LaplacianForm,
    f: &[Real],
    out: &mut [Real],
) {
    s.check(neighbors, f.len(), out.len());
    let x = s.positions;
    let h = kernel.support();
    let eta2 = BROOKSHAW_ETA2 * h * h;
    out.par_iter_mut().enumerate().for_each(|(i, out)| {
        let (xi, fi) = (x[i], f[i]);
        *out = neighbors
            .of(i)
            .iter()
            .map(|&j| {
                let j = j as usize;
                let xij = xi - x[j];
                let r = xij.norm();
                match form {
                    LaplacianForm::Plain => s.volume(j) * f[j] * kernel.laplacian(r),
                    LaplacianForm::Corrected => s.volume(j) * (f[j] - fi) * kernel.laplacian(r),
                    LaplacianForm::Brookshaw => {
                        // `x_ij . grad W_ij` through the gradient, which is
                        // zero at r = 0 (where `r w'` is NaN for viscosity).
                        let radial = xij.dot(&kernel.gradient(&xij, r));
                        2.0 * s.volume(j) * (fi - f[j]) * radial / (r * r + eta2)
                    }
                }
            })
            .sum();
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::KernelKind;
    use crate::neighbors::{CandidateSearch, UniformGrid};
    use crate::testing::uniform;

    const REST_DENSITY: Real = 1000.0;
    /// Jitter of every coordinate, in spacings: uniform in `[-0.2, 0.2]`.
    const JITTER: Real = 0.2;
    /// Support radius in spacings.
    const H_OVER_SPACING: Real = 2.0;
    /// Kernels of the 3D tables (all smooth at the origin).
    const KINDS_3D: [KernelKind; 3] = [
        KernelKind::CubicSpline,
        KernelKind::WendlandC2,
        KernelKind::Poly6,
    ];
    /// Kernels of the 2D tables. Poly6 is left out: with `h = 2 dx` its
    /// lattice sums in 2D happen to reproduce linear fields exactly (the
    /// density sum and the gradient moment are both `51/16` in lattice
    /// units), so its measured error is round-off and no margin applies.
    const KINDS_2D: [KernelKind; 2] = [KernelKind::CubicSpline, KernelKind::WendlandC2];
    /// Particles per side of the `[-1/2, 1/2]^d` block, coarse to fine:
    /// spacings 1/16, 1/24, 1/32 in 3D and 1/16, 1/32, 1/64 in 2D.
    const SIDES_3D: [usize; 3] = [17, 25, 33];
    const SIDES_2D: [usize; 3] = [17, 33, 65];
    /// Factor between a measured error and the bound the tests assert.
    const MARGIN: Real = 1.5;
    /// Slope and offset of the linear test field `a . x + b`.
    const SLOPE: [Real; 3] = [1.0, -2.0, 0.5];
    const OFFSET: Real = 3.0;

    /// A square (2D) or cubic (3D) lattice filling `[-1/2, 1/2]^d`, maybe
    /// jittered, with `h = 2 * spacing`, masses `rho0 * spacing^d` and the
    /// density sum as densities, so that `V_j` is the SPH volume.
    #[derive(Debug)]
    struct Block {
        dim: usize,
        jittered: bool,
        spacing: Real,
        kernel: Kernel,
        positions: Vec<Vector>,
        masses: Vec<Real>,
        densities: Vec<Real>,
        neighbors: NeighborList,
        /// Particles at least `2h` from every face: their support, and the
        /// supports of their neighbours (whose densities enter `V_j`), lie
        /// inside the block.
        interior: Vec<usize>,
    }

    impl Block {
        fn new(kind: KernelKind, dim: usize, per_side: usize, jittered: bool) -> Self {
            let spacing = 1.0 / (per_side - 1) as Real;
            let h = H_OVER_SPACING * spacing;
            let kernel = Kernel::new(kind, dim, h);
            let mut seed = 0x5eed + per_side as u64;
            let layers = if dim == 3 { per_side } else { 1 };
            let corner = Vector::new(0.5, 0.5, if dim == 3 { 0.5 } else { 0.0 });
            let mut positions = Vec::with_capacity(per_side.pow(dim as u32));
            for k in 0..layers {
                for j in 0..per_side {
                    for i in 0..per_side {
                        let mut p = Vector::new(i as Real, j as Real, k as Real) * spacing - corner;
                        if jittered {
                            for axis in 0..dim {
                                p[axis] += (2.0 * uniform(&mut seed) - 1.0) * JITTER * spacing;
                            }
                        }
                        positions.push(p);
                    }
                }
            }
            let margin = Vector::repeat(0.5 + h);
            let mut grid = UniformGrid::new(-margin, margin, h).expect("a small grid");
            grid.rebuild(&positions);
            let mut neighbors = NeighborList::default();
            neighbors.build(&grid, &positions, h);
            let masses = vec![REST_DENSITY * spacing.powi(dim as i32); positions.len()];
            let densities = (0..positions.len())
                .map(|i| {
                    neighbors
                        .of(i)
                        .iter()
                        .map(|&j| {
                            let j = j as usize;
                            masses[j] * kernel.value((positions[i] - positions[j]).norm())
                        })
                        .sum()
                })
                .collect();
            let inner = 0.5 - 2.0 * h;
            let interior = (0..positions.len())
                .filter(|&i| (0..dim).all(|axis| positions[i][axis].abs() <= inner))
                .collect();
            Self {
                dim,
                jittered,
                spacing,
                kernel,
                positions,
                masses,
                densities,
                neighbors,
                interior,
            }
        }

        fn h(&self) -> Real {
            self.kernel.support()
        }

        fn samples(&self) -> Samples<'_> {
            Samples {
                positions: &self.positions,
                masses: &self.masses,
                densities: &self.densities,
            }
        }

        /// `v` with the components beyond the block's dimension zeroed.
        fn project(&self, v: Vector) -> Vector {
            if self.dim == 3 {
                v
            } else {
                Vector::new(v.x, v.y, 0.0)
            }
        }

        fn scalar(&self, f: impl Fn(&Vector) -> Real) -> Vec<Real> {
            self.positions.iter().map(f).collect()
        }

        fn vector(&self, f: impl Fn(&Vector) -> Vector) -> Vec<Vector> {
            self.positions.iter().map(f).collect()
        }

        fn value(&self, f: &[Real]) -> Vec<Real> {
            let mut out = vec![Real::NAN; self.positions.len()];
            value(&self.samples(), &self.neighbors, &self.kernel, f, &mut out);
            out
        }

        fn gradient(&self, form: GradientForm, f: &[Real]) -> Vec<Vector> {
            let mut out = vec![Vector::repeat(Real::NAN); self.positions.len()];
            gradient(
                &self.samples(),
                &self.neighbors,
                &self.kernel,
                form,
                f,
                &mut out,
            );
            out
        }

        fn divergence(&self, form: DivergenceForm, f: &[Vector]) -> Vec<Real> {
            let mut out = vec![Real::NAN; self.positions.len()];
            divergence(
                &self.samples(),
                &self.neighbors,
                &self.kernel,
                form,
                f,
                &mut out,
            );
            out
        }

        fn laplacian(&self, form: LaplacianForm, f: &[Real]) -> Vec<Real> {
            let mut out = vec![Real::NAN; self.positions.len()];
            laplacian(
                &self.samples(),
                &self.neighbors,
                &self.kernel,
                form,
                f,
                &mut out,
            );
            out
        }

        /// Root mean square of `err(i)` over the interior particles.
        fn rms(&self, err: impl Fn(usize) -> Real) -> Real {
            let sum: Real = self.interior.iter().map(|&i| err(i).powi(2)).sum();
            (sum / self.interior.len() as Real).sqrt()
        }
    }

    fn lattice_name(jittered: bool) -> &'static str {
        if jittered { "jittered" } else { "regular" }
    }

    /// One line of an error table: the block's kernel, lattice and spacing,
    /// and one error per column.
    #[derive(Debug)]
    struct Row {
        dim: usize,
        kind: KernelKind,
        jittered: bool,
        spacing: Real,
        h: Real,
        errors: Vec<Real>,
    }

    impl Row {
        fn name(&self) -> String {
            format!(
                "{:?} in {}D on the {} lattice with spacing {:.5}",
                self.kind,
                self.dim,
                lattice_name(self.jittered),
                self.spacing
            )
        }
    }

    /// Measures every block of the tables: 3D with [`KINDS_3D`], 2D with
    /// [`KINDS_2D`], regular then jittered, each kernel coarse to fine (so
    /// `rows.chunks(3)` are the spacings of one kernel and lattice).
    fn sweep(measure: impl Fn(&Block) -> Vec<Real>) -> Vec<Row> {
        let mut rows = Vec::new();
        for (dim, kinds, sides) in [(3, &KINDS_3D[..], SIDES_3D), (2, &KINDS_2D[..], SIDES_2D)] {
            for jittered in [false, true] {
                for &kind in kinds {
                    for side in sides {
                        let block = Block::new(kind, dim, side, jittered);
                        assert!(block.interior.len() >= 40, "too few interior particles");
                        rows.push(Row {
                            dim,
                            kind,
                            jittered,
                            spacing: block.spacing,
                            h: block.h(),
                            errors: measure(&block),
                        });
                    }
                }
            }
        }
        rows
    }

    fn print_table(title: &str, columns: &[&str], rows: &[Row]) {
        println!("\n{title}");
        let mut header = format!(
            "{:<2} {:<12} {:<9} {:>8} {:>8}",
            "d", "kernel", "lattice", "spacing", "h"
        );
        for c in columns {
            header += &format!(" {c:>10}");
        }
        println!("{header}");
        for row in rows {
            let mut line = format!(
                "{:<2} {:<12} {:<9} {:>8.5} {:>8.5}",
                row.dim,
                format!("{:?}", row.kind),
                lattice_name(row.jittered),
                row.spacing,
                row.h
            );
            for e in &row.errors {
                line += &format!(" {e:>10.3e}");
            }
            println!("{line}");
        }
    }

    /// Asserts every error of `rows` below `MARGIN` times the value
    /// `measured(dim, kind, jittered)` gives for its column (the largest
    /// error measured over the spacings, rounded up; infinity where a
    /// column is not bounded).
    fn assert_measured_bounds<const N: usize>(
        what: &str,
        columns: &[&str; N],
        rows: &[Row],
        measured: impl Fn(usize, KernelKind, bool) -> [Real; N],
    ) {
        for row in rows {
            let bounds = measured(row.dim, row.kind, row.jittered);
            for ((column, error), bound) in columns.iter().zip(&row.errors).zip(bounds) {
                assert!(
                    *error < MARGIN * bound,
                    "{what}, {column}, {}: error {error:.3e} above {MARGIN} x {bound:.3e}",
                    row.name()
                );
            }
        }
    }

    /// `(h_coarse / h_fine)` of a chunk of rows from [`sweep`].
    fn refinement(group: &[Row]) -> Real {
        group[0].h / group[group.len() - 1].h
    }

    /// Whether `a` and `b` agree to `tol` relative to their size.
    fn close(a: Real, b: Real, tol: Real) -> bool {
        (a - b).abs() <= tol * a.abs().max(b.abs())
    }

    /// The forms that subtract `f_i` (corrected gradient, density-weighted
    /// gradient, corrected divergence, corrected and Brookshaw Laplacians)
    /// are exactly zero for a constant field at every particle, boundary
    /// included, on any particle set; the others are not. On the interior of
    /// a regular lattice symmetry cancels the plain and symmetric gradients
    /// and the plain divergence too (to round-off), and the value operator
    /// reproduces the constant; on a jittered lattice they carry an error of
    /// order `f / h`, the symmetric gradient about twice the plain one. The
    /// plain Laplacian of a constant is not zero even on a regular lattice:
    /// the lattice sum of `Lap W` does not vanish at `h = 2 dx`.
    #[test]
    fn corrected_forms_vanish_exactly_on_a_constant_field() {
        const F: Real = 3.0;
        let rows = sweep(|b| {
            let n = b.positions.len();
            let h = b.h();
            let f = vec![F; n];
            let u = vec![b.project(Vector::new(F, -F, F)); n];
            let exact_zero = |what: &str, out: &[Real]| {
                let bad = out.iter().position(|&v| v != 0.0);
                assert!(
                    bad.is_none(),
                    "{what} of a constant, {:?} {}D {}: {:?} at particle {bad:?}",
                    b.kernel.kind(),
                    b.dim,
                    lattice_name(b.jittered),
                    bad.map(|i| out[i])
                );
            };
            for form in [GradientForm::Corrected, GradientForm::DensityWeighted] {
                let g = b.gradient(form, &f);
                let norms: Vec<Real> = g.iter().map(|g| g.norm()).collect();
                exact_zero(&format!("{form:?} gradient"), &norms);
            }
            exact_zero(
                "corrected divergence",
                &b.divergence(DivergenceForm::Corrected, &u),
            );
            for form in [LaplacianForm::Corrected, LaplacianForm::Brookshaw] {
                exact_zero(&format!("{form:?} Laplacian"), &b.laplacian(form, &f));
            }
            let v = b.value(&f);
            let plain = b.gradient(GradientForm::Plain, &f);
            let symmetric = b.gradient(GradientForm::Symmetric, &f);
            let div = b.divergence(DivergenceForm::Plain, &u);
            let lap = b.laplacian(LaplacianForm::Plain, &f);
            vec![
                b.rms(|i| (v[i] - F) / F),
                b.rms(|i| plain[i].norm() * h / F),
                b.rms(|i| symmetric[i].norm() * h / F),
                b.rms(|i| div[i] * h / (F * u[i].norm())),
                b.rms(|i| lap[i] * h * h / F),
            ]
        });
        let columns = ["value", "grad plain", "grad sym", "div plain", "lap plain"];
        print_table(
            "constant field f = 3: rms of |<f> - f| / f, |grad| h / f, |div| h / |f|, |lap| h^2 / f \
             (corrected forms: exactly 0, asserted)",
            &columns,
            &rows,
        );
        for row in &rows {
            let [value, plain, symmetric, div, lap] = row.errors[..] else {
                unreachable!("five columns")
            };
            // Measured minimum over the rows, in units of f/h or f/h^2.
            assert!(lap > 0.134 / MARGIN, "plain Laplacian, {}", row.name());
            if row.jittered {
                // Measured: value 4.03e-2 at most; plain gradient 0.205,
                // symmetric 0.411, plain divergence 3.94e-2 at least.
                assert!(value < MARGIN * 4.03e-2, "value, {}", row.name());
                assert!(plain > 0.205 / MARGIN, "plain gradient, {}", row.name());
                assert!(symmetric > 0.411 / MARGIN, "symmetric, {}", row.name());
                assert!(
                    symmetric > 1.5 * plain,
                    "symmetric vs plain, {}",
                    row.name()
                );
                assert!(div > 3.94e-2 / MARGIN, "plain divergence, {}", row.name());
            } else {
                for (what, e) in [
                    ("value", value),
                    ("plain gradient", plain),
                    ("symmetric gradient", symmetric),
                    ("plain divergence", div),
                ] {
                    assert!(
                        e < 1e-12,
                        "{what} on the regular lattice, {}: {e:e}",
                        row.name()
                    );
                }
            }
        }
    }

    /// Every gradient form recovers the slope `a` of a linear field
    /// `a . x + b` with the right sign, and the value operator recovers the
    /// field. On the interior of a regular lattice the four forms coincide
    /// (the constant part cancels by symmetry), the value is exact and the
    /// error, a lattice-sum error of the kernel, is the same at every
    /// spacing. On a jittered lattice the forms that subtract `f_i` keep
    /// that spacing-independent error (about 10-15 %: first-order
    /// inconsistency), while the plain form adds `f_i sum_j V_j grad W_ij`,
    /// of order `b / h`, which grows under refinement; the symmetric form
    /// doubles it.
    #[test]
    fn gradients_of_a_linear_field_recover_its_slope() {
        let rows = sweep(|b| {
            let a = b.project(Vector::from(SLOPE));
            let f = b.scalar(|x| a.dot(x) + OFFSET);
            let v = b.value(&f);
            let mut errors = vec![b.rms(|i| (v[i] - f[i]) / f[i])];
            for form in GradientForm::ALL {
                let g = b.gradient(form, &f);
                if form == GradientForm::Corrected || !b.jittered {
                    let wrong = b.interior.iter().find(|&&i| g[i].dot(&a) <= 0.0);
                    assert!(
                        wrong.is_none(),
                        "{form:?} gradient points against the slope"
                    );
                }
                errors.push(b.rms(|i| (g[i] - a).norm() / a.norm()));
            }
            errors
        });
        let columns = ["value", "plain", "corrected", "density-w", "symmetric"];
        print_table(
            "linear field f = a.x + 3, a = (1, -2, 0.5): rms |<f> - f| / f and |grad f - a| / |a|",
            &columns,
            &rows,
        );
        // Measured: the largest error over the three spacings, rounded up.
        assert_measured_bounds("linear field", &columns, &rows, |dim, kind, jittered| {
            use KernelKind::*;
            match (dim, kind, jittered) {
                (3, CubicSpline, false) => [1e-12, 2.01e-2, 2.01e-2, 2.01e-2, 2.01e-2],
                (3, WendlandC2, false) => [1e-12, 4.99e-2, 4.99e-2, 4.99e-2, 4.99e-2],
                (3, Poly6, false) => [1e-12, 5.46e-2, 5.46e-2, 5.46e-2, 5.46e-2],
                (3, CubicSpline, true) => [4.03e-2, 8.27, 0.113, 0.129, 16.6],
                (3, WendlandC2, true) => [3.77e-2, 10.1, 0.156, 0.164, 20.2],
                (3, Poly6, true) => [3.75e-2, 4.36, 9.04e-2, 0.116, 8.74],
                (2, CubicSpline, false) => [1e-12, 1.23e-2, 1.23e-2, 1.23e-2, 1.23e-2],
                (2, WendlandC2, false) => [1e-12, 5.92e-2, 5.92e-2, 5.92e-2, 5.92e-2],
                (2, CubicSpline, true) => [3.78e-2, 17.8, 0.118, 0.133, 35.7],
                (2, WendlandC2, true) => [3.23e-2, 20.9, 0.165, 0.172, 41.8],
                _ => unreachable!("no such block"),
            }
        });
        for group in rows.chunks(3) {
            let (coarse, fine) = (&group[0], &group[2]);
            for row in group {
                let [_, plain, corrected, density, symmetric] = row.errors[..] else {
                    unreachable!("five columns")
                };
                if row.jittered {
                    assert!(corrected < plain && density < plain, "{}", row.name());
                    assert!(plain < symmetric, "{}", row.name());
                } else {
                    for e in [corrected, density, symmetric] {
                        assert!(close(e, plain, 1e-9), "forms differ: {}", row.name());
                    }
                }
            }
            if coarse.jittered {
                // Plain: error ~ b / h. Corrected: independent of h.
                let growth = fine.errors[1] / coarse.errors[1];
                assert!(
                    growth > 0.75 * refinement(group),
                    "{}: {growth}",
                    fine.name()
                );
                assert!(
                    close(fine.errors[2], coarse.errors[2], 0.1),
                    "{}",
                    fine.name()
                );
            } else {
                for column in 1..5 {
                    let (e0, e1) = (coarse.errors[column], fine.errors[column]);
                    assert!(close(e0, e1, 1e-6), "{}: {e0} vs {e1}", fine.name());
                }
            }
        }
    }

    /// The Laplacian of `|x|^2` is `2d`. On the interior of a regular
    /// lattice the corrected and Brookshaw forms give the same error at
    /// every spacing (the linear part of `f_j - f_i` cancels by symmetry,
    /// the quadratic part is scale-free), while the plain form carries
    /// `f_i sum_j V_j Lap W_ij`, of order `f / h^2`, and so grows at least
    /// as `1 / h^2`. On a jittered lattice the corrected form is more
    /// accurate than the plain one and Brookshaw's, which needs only first
    /// derivatives of the kernel, more accurate than both. None converges
    /// there: their first moment does not vanish on disordered particles,
    /// so the gradient of `f` leaks in as `|grad f| / h`.
    #[test]
    fn laplacians_of_a_quadratic_field_recover_2d() {
        let rows = sweep(|b| {
            let f = b.scalar(|x| x.norm_squared());
            let exact = 2.0 * b.dim as Real;
            LaplacianForm::ALL
                .iter()
                .map(|&form| {
                    let l = b.laplacian(form, &f);
                    b.rms(|i| (l[i] - exact) / exact)
                })
                .collect()
        });
        let columns = ["plain", "corrected", "brookshaw"];
        print_table(
            "quadratic field f = |x|^2: rms |lap f - 2d| / 2d",
            &columns,
            &rows,
        );
        // Measured: the largest error over the three spacings, rounded up.
        // The plain form is not bounded: its error grows as 1 / h^2.
        assert_measured_bounds("|x|^2", &columns, &rows, |dim, kind, jittered| {
            use KernelKind::*;
            let inf = Real::INFINITY;
            match (dim, kind, jittered) {
                (3, CubicSpline, false) => [inf, 8.80e-2, 8.43e-3],
                (3, WendlandC2, false) => [inf, 0.181, 7.78e-2],
                (3, Poly6, false) => [inf, 0.328, 2.87e-2],
                (3, CubicSpline, true) => [inf, 1.60, 0.851],
                (3, WendlandC2, true) => [inf, 1.49, 1.05],
                (3, Poly6, true) => [inf, 1.66, 0.461],
                (2, CubicSpline, false) => [inf, 2.62e-2, 2.05e-2],
                (2, WendlandC2, false) => [inf, 4.28e-2, 9.03e-2],
                (2, CubicSpline, true) => [inf, 4.57, 3.02],
                (2, WendlandC2, true) => [inf, 3.95, 3.54],
                _ => unreachable!("no such block"),
            }
        });
        for group in rows.chunks(3) {
            let (coarse, fine) = (&group[0], &group[2]);
            for row in group {
                let [plain, corrected, brookshaw] = row.errors[..] else {
                    unreachable!("three columns")
                };
                assert!(brookshaw < plain, "{}", row.name());
                if row.jittered {
                    assert!(brookshaw < corrected && corrected < plain, "{}", row.name());
                }
            }
            let growth = fine.errors[0] / coarse.errors[0];
            assert!(
                growth > refinement(group).powi(2),
                "{}: {growth}",
                fine.name()
            );
            if !coarse.jittered {
                for column in 1..3 {
                    let (e0, e1) = (coarse.errors[column], fine.errors[column]);
                    assert!(close(e0, e1, 1e-6), "{}: {e0} vs {e1}", fine.name());
                }
            }
        }
    }

    /// The divergence of `(x, 2y, -z)` is `2` in 3D (`(x, 2y, 0)`: 3 in
    /// 2D). On a regular lattice the plain and corrected forms agree; on a
    /// jittered one the corrected form keeps its spacing-independent error
    /// while the plain one, off by `f_i . sum_j V_j grad W_ij`, is worse
    /// and grows under refinement.
    #[test]
    fn divergence_of_a_linear_vector_field_is_its_trace() {
        let rows = sweep(|b| {
            let u = b.vector(|x| b.project(Vector::new(x.x, 2.0 * x.y, -x.z)));
            let exact = if b.dim == 3 { 2.0 } else { 3.0 };
            DivergenceForm::ALL
                .iter()
                .map(|&form| {
                    let d = b.divergence(form, &u);
                    b.rms(|i| (d[i] - exact) / exact)
                })
                .collect()
        });
        let columns = ["plain", "corrected"];
        print_table(
            "vector field (x, 2y, -z): rms |div f - tr| / tr",
            &columns,
            &rows,
        );
        // Measured: the largest error over the three spacings, rounded up.
        assert_measured_bounds("(x, 2y, -z)", &columns, &rows, |dim, kind, jittered| {
            use KernelKind::*;
            match (dim, kind, jittered) {
                (3, CubicSpline, false) => [2.01e-2, 2.01e-2],
                (3, WendlandC2, false) => [4.99e-2, 4.99e-2],
                (3, Poly6, false) => [5.46e-2, 5.46e-2],
                (3, CubicSpline, true) => [0.960, 8.20e-2],
                (3, WendlandC2, true) => [1.18, 0.131],
                (3, Poly6, true) => [0.508, 6.62e-2],
                (2, CubicSpline, false) => [1.23e-2, 1.23e-2],
                (2, WendlandC2, false) => [5.92e-2, 5.92e-2],
                (2, CubicSpline, true) => [1.72, 7.58e-2],
                (2, WendlandC2, true) => [2.02, 0.135],
                _ => unreachable!("no such block"),
            }
        });
        for group in rows.chunks(3) {
            let (coarse, fine) = (&group[0], &group[2]);
            for row in group {
                let [plain, corrected] = row.errors[..] else {
                    unreachable!("two columns")
                };
                if row.jittered {
                    assert!(corrected < plain, "{}", row.name());
                } else {
                    assert!(close(plain, corrected, 1e-9), "{}", row.name());
                }
            }
            if coarse.jittered {
                let growth = fine.errors[0] / coarse.errors[0];
                assert!(
                    growth > 0.75 * refinement(group),
                    "{}: {growth}",
                    fine.name()
                );
                assert!(
                    close(fine.errors[1], coarse.errors[1], 0.1),
                    "{}",
                    fine.name()
                );
            }
        }
    }

    /// Slices of different lengths are a programming error: the operators
    /// refuse them at entry instead of reading past a field.
    #[test]
    #[should_panic(expected = "one field value per particle")]
    fn operators_refuse_a_field_of_the_wrong_length() {
        let b = Block::new(KernelKind::CubicSpline, 2, 5, false);
        let mut out = vec![0.0; b.positions.len()];
        let short = vec![1.0; b.positions.len() - 1];
        laplacian(
            &b.samples(),
            &b.neighbors,
            &b.kernel,
            LaplacianForm::Brookshaw,
            &short,
            &mut out,
        );
    }
}
