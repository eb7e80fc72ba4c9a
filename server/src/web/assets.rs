//! What the viewer's listener serves besides the service: the page and
//! its scripts, embedded in the binary (no build step, nothing fetched
//! from elsewhere, so the page works on a machine with no internet), and
//! the shipped scenes a person may start a session from.

/// A file the page loads: its name under `/`, its media type, its text.
#[derive(Debug, Clone, Copy)]
pub struct Asset {
    pub name: &'static str,
    pub media_type: &'static str,
    pub text: &'static str,
}

const JS: &str = "text/javascript; charset=utf-8";

/// The page (`/` serves `index.html`) and every file it loads.
pub const ASSETS: &[Asset] = &[
    Asset {
        name: "index.html",
        media_type: "text/html; charset=utf-8",
        text: include_str!("../../web/index.html"),
    },
    Asset {
        name: "viewer.css",
        media_type: "text/css; charset=utf-8",
        text: include_str!("../../web/viewer.css"),
    },
    Asset {
        name: "viewer.js",
        media_type: JS,
        text: include_str!("../../web/viewer.js"),
    },
    Asset {
        name: "codec.js",
        media_type: JS,
        text: include_str!("../../web/codec.js"),
    },
    Asset {
        name: "render.js",
        media_type: JS,
        text: include_str!("../../web/render.js"),
    },
    Asset {
        name: "plot.js",
        media_type: JS,
        text: include_str!("../../web/plot.js"),
    },
];

/// The shipped scenes a session may start from, by name: those that need
/// no file beside them (a mesh body's scene names its mesh files, which a
/// page cannot send with the TOML).
pub const SCENES: &[(&str, &str)] = &[
    (
        "brittle_beam",
        include_str!("../../../scenes/brittle_beam.toml"),
    ),
    ("dam_break", include_str!("../../../scenes/dam_break.toml")),
    (
        "dam_break_2d",
        include_str!("../../../scenes/dam_break_2d.toml"),
    ),
    (
        "ductile_spin",
        include_str!("../../../scenes/ductile_spin.toml"),
    ),
    (
        "elastic_beam",
        include_str!("../../../scenes/elastic_beam.toml"),
    ),
    (
        "floating_box",
        include_str!("../../../scenes/floating_box.toml"),
    ),
    (
        "jelly_drop",
        include_str!("../../../scenes/jelly_drop.toml"),
    ),
    (
        "modal_beam",
        include_str!("../../../scenes/modal_beam.toml"),
    ),
    (
        "notched_spin",
        include_str!("../../../scenes/notched_spin.toml"),
    ),
    (
        "shell_balloon",
        include_str!("../../../scenes/shell_balloon.toml"),
    ),
    (
        "shell_plate",
        include_str!("../../../scenes/shell_plate.toml"),
    ),
];

/// The scenes as the page reads them: `[{name, file, toml}]`.
pub fn scenes_json() -> String {
    let list: Vec<_> = SCENES
        .iter()
        .map(|(name, toml)| {
            serde_json::json!({
                "name": name,
                "file": format!("scenes/{name}.toml"),
                "toml": toml,
            })
        })
        .collect();
    serde_json::Value::Array(list).to_string()
}
