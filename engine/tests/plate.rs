//! The clamped square plate every shell code starts from, on the thin
//! shells' static route (`engine/src/shell/`): the quadtree over the
//! parametric domain, MLS shape functions with their second derivatives,
//! Gauss cells, the Kirchhoff–Love energy, penalty supports.
//!
//! A clamped square plate of side `a` under uniform pressure `q` deflects
//! at its centre by `0.00126 q a^4 / D` (Timoshenko & Woinowsky-Krieger,
//! *Theory of Plates and Shells*, 1959, Table 35, nu = 0.3). The clamp
//! holds the displacement and the normal slope along the edges.
//!
//! Measured (the test prints them all): with the supports' `beta = 10`
//! the centre deflection is 0.848, 0.939 and 0.991 of Timoshenko's at 8,
//! 16 and 32 cells a side. The clamp's strength matters: at 16 cells
//! `beta = 1` gave 1.387 (too weak a clamp: the plate turns towards a
//! simply supported one, 3.2 times as soft) and `beta = 100` 0.885 (the
//! penalty stiffening the approximation near the edges); so does the
//! quadrature: one 4 x 4 rule per leaf instead of 2 x 2 cells of it gave
//! 1.403 (the shape functions' second derivatives jump inside a leaf,
//! where the weight's spline changes branch, and one rule misses it).

mod shell_charts;

use meshless_engine::cancel::Cancel;
use meshless_engine::math::{Real, Vector};
use meshless_engine::shell::{Load, Material, ShellModel, ShellParams, StaticParams, SupportKind};
use shell_charts::UnitSquare;

/// Timoshenko & Woinowsky-Krieger's coefficient for the clamped square
/// plate's centre deflection, `w = alpha q a^4 / D` (nu = 0.3).
const TIMOSHENKO: Real = 0.00126;

/// The clamped plate's centre deflection over `q a^4 / D` with `cells`
/// a side, the supports' penalty scale `beta`, `subdivision^2`
/// integration cells per leaf (a = 1, linear route).
fn clamped_plate(cells: Real, beta: Real, subdivision: usize) -> Real {
    let material = Material {
        thickness: 0.01,
        density: 0.0,
        young: 1.0e6,
        poisson: 0.3,
    };
    let mut params = ShellParams::new(1.0 / cells);
    params.quadtree.subdivision = subdivision;
    let model = ShellModel::new(
        &UnitSquare,
        [0.0, 0.0],
        [1.0, 1.0],
        material,
        &params,
        &Cancel::new(),
    )
    .expect("the plate discretises");
    let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let mut supports = Vec::new();
    for k in 0..4 {
        let (from, to) = (corners[k], corners[(k + 1) % 4]);
        let across = [to[1] - from[1], from[0] - to[0]];
        let kinds = [
            SupportKind::Displacement(Vector::x()),
            SupportKind::Displacement(Vector::y()),
            SupportKind::Displacement(Vector::z()),
            SupportKind::Slope(across),
        ];
        supports.extend(
            model
                .edge_supports(from, to, cells as usize, &kinds)
                .expect("on the chart"),
        );
    }
    let q = 1.0;
    let load = Load {
        pressure: q,
        ..Load::default()
    };
    let params = StaticParams {
        penalty: beta,
        linear: true,
        ..StaticParams::default()
    };
    let solution = model
        .solve_static(&load, &supports, &params, &Cancel::new())
        .expect("the plate is clamped");
    let w = model
        .displacement_at([0.5, 0.5], &solution.displacement)
        .expect("the centre")[2];
    w * material.bending_stiffness() / q / TIMOSHENKO
}

/// The centre deflection converges on Timoshenko's as the cells shrink,
/// to within 1 % at 32 cells a side; at 16 cells a weaker clamp lets the
/// plate sag further, a stiffer one less, and one Gauss rule per leaf
/// misjudges the bending energy (the test could fail every way; it
/// prints the figures the module's documentation gives).
#[test]
fn a_clamped_square_plate_deflects_as_timoshenko_says() {
    let ratios: Vec<Real> = [8.0, 16.0, 32.0]
        .iter()
        .map(|&n| clamped_plate(n, 10.0, 2))
        .collect();
    eprintln!("centre deflection / Timoshenko at 8, 16, 32 cells: {ratios:.3?}");
    let errors: Vec<Real> = ratios.iter().map(|r| (r - 1.0).abs()).collect();
    assert!(errors[0] > errors[1] && errors[1] > errors[2], "{ratios:?}");
    assert!(errors[2] < 0.01, "{ratios:?}");
    let (weak, stiff, one_rule) = (
        clamped_plate(16.0, 1.0, 2),
        clamped_plate(16.0, 100.0, 2),
        clamped_plate(16.0, 10.0, 1),
    );
    eprintln!(
        "at 16 cells: beta = 1 {weak:.3}, beta = 100 {stiff:.3}, one rule per leaf {one_rule:.3}"
    );
    assert!(weak > ratios[1] + 0.03, "a weaker clamp sags more: {weak}");
    assert!(
        stiff < ratios[1] - 0.005,
        "a stiffer clamp sags less: {stiff}"
    );
    assert!(one_rule > ratios[1] + 0.01, "one rule per leaf: {one_rule}");
}
