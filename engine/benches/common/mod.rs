//! The scene the benchmarks share: the 3D dam break of PERFORMANCE.md, a
//! 1 x 2 x 1 m column in a 4 x 3 x 1 m box, steps of 1/240 s, WCSPH with
//! the default cubic-spline pair and no XSPH.

use meshless_engine::Scene;

/// The dam-break column at `spacing` (0.05 m gives 16,000 particles,
/// 0.0237 m 148,176).
pub fn dam_break(spacing: f64) -> Scene {
    let text = format!(
        r#"
[domain]
min = [0.0, 0.0, 0.0]
max = [4.0, 3.0, 1.0]
[time]
dt = 0.004166666666666667
[[systems]]
kind = "fluid"
spacing = {spacing}
stiffness = 5.7e5
xsph = 0.0
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [1.0, 2.0, 1.0] }}
"#
    );
    Scene::from_toml_str(&text).expect("bench scene")
}
