//! Scene files as a client sends them: the TOML text, with every mesh
//! file it names carried inline.
//!
//! A server reads no file a client names, or only those in its own mesh
//! directory, so a scene on the client's machine that names
//! `meshes/box.ply` would not build there. [`read_scene_file`] reads each
//! such mesh beside the scene file and puts its bytes into the shape
//! (`data = { format, base64 }`), keeping `path` as the mesh's name.

use crate::ClientError;
use base64::Engine as _;
use base64::engine::general_purpose::STANDARD;
use std::path::Path;

/// Largest mesh file read: a server refuses larger ones anyway (its
/// `--max-mesh-mb`, 16 MB by default).
const MAX_MESH_BYTES: u64 = 256 << 20;

/// Reads a TOML scene file and inlines the mesh files its shapes name
/// (relative paths from the scene file's directory). A shape that already
/// has `data` is left as it is.
///
/// # Errors
/// [`ClientError::Scene`] when the scene or a mesh cannot be read, the
/// TOML does not parse, or a mesh path has no `.obj` or `.ply` extension.
pub fn read_scene_file(path: &Path) -> Result<String, ClientError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| ClientError::Scene(format!("cannot read {}: {e}", path.display())))?;
    inline_meshes(&text, path.parent().unwrap_or(Path::new("")))
        .map_err(|e| ClientError::Scene(format!("{}: {e}", path.display())))
}

/// `text` (a scene's TOML) with the mesh files it names, relative to
/// `base`, carried inline; the text unchanged when it names none.
///
/// # Errors
/// A message naming the system and the file.
pub fn inline_meshes(text: &str, base: &Path) -> Result<String, String> {
    let mut scene: toml::Table = toml::from_str(text).map_err(|e| e.to_string())?;
    let Some(toml::Value::Array(systems)) = scene.get_mut("systems") else {
        return Ok(text.to_owned());
    };
    let mut inlined = 0;
    for (s, system) in systems.iter_mut().enumerate() {
        let Some(shape) = system.get_mut("shape").and_then(toml::Value::as_table_mut) else {
            continue;
        };
        let is_mesh = shape.get("type").and_then(toml::Value::as_str) == Some("mesh");
        if !is_mesh || shape.contains_key("data") {
            continue;
        }
        let Some(name) = shape.get("path").and_then(toml::Value::as_str) else {
            continue;
        };
        let file = base.join(name);
        let format = match file.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("obj") => "obj",
            Some(e) if e.eq_ignore_ascii_case("ply") => "ply",
            _ => {
                return Err(format!(
                    "systems[{s}].shape.path {name:?}: give an .obj or .ply file"
                ));
            }
        };
        let bytes = read_mesh(&file)
            .map_err(|e| format!("systems[{s}].shape.path: {}: {e}", file.display()))?;
        let mut data = toml::Table::new();
        data.insert("format".into(), format.into());
        data.insert("base64".into(), STANDARD.encode(bytes).into());
        shape.insert("data".into(), data.into());
        inlined += 1;
    }
    if inlined == 0 {
        return Ok(text.to_owned());
    }
    toml::to_string(&scene).map_err(|e| e.to_string())
}

/// A regular file of at most [`MAX_MESH_BYTES`].
fn read_mesh(file: &Path) -> std::io::Result<Vec<u8>> {
    let metadata = std::fs::metadata(file)?;
    if !metadata.is_file() || metadata.len() > MAX_MESH_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("not a regular file of at most {MAX_MESH_BYTES} bytes"),
        ));
    }
    std::fs::read(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meshes_beside_the_scene_travel_inline() {
        let dir = std::env::temp_dir().join(format!("meshless-inline-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("meshes")).expect("dir");
        std::fs::write(dir.join("meshes/a.OBJ"), "v 0 0 0\n").expect("mesh");
        let scene = dir.join("scene.toml");
        std::fs::write(
            &scene,
            "name = \"s\"\n[[systems]]\nkind = \"fluid\"\n\
             [[systems]]\nkind = \"rigid_body\"\n\
             shape = { type = \"mesh\", path = \"meshes/a.OBJ\", scale = 2.0 }\n\
             [[systems]]\nkind = \"rigid_body\"\nshape = { type = \"sphere\", radius = 1.0 }\n",
        )
        .expect("scene");
        let text = read_scene_file(&scene).expect("inlined");
        let table: toml::Table = toml::from_str(&text).expect("toml");
        let shape = &table["systems"][1]["shape"];
        assert_eq!(shape["path"].as_str(), Some("meshes/a.OBJ"));
        assert_eq!(shape["scale"].as_float(), Some(2.0));
        assert_eq!(shape["data"]["format"].as_str(), Some("obj"));
        let bytes = STANDARD
            .decode(shape["data"]["base64"].as_str().expect("text"))
            .expect("base64");
        assert_eq!(bytes, b"v 0 0 0\n");
        assert!(table["systems"][2]["shape"].get("data").is_none());

        std::fs::write(
            &scene,
            "[[systems]]\nshape = { type = \"mesh\", path = \"x.stl\" }\n",
        )
        .expect("scene");
        let err = read_scene_file(&scene).expect_err("stl");
        assert!(err.to_string().contains(".obj or .ply"), "{err}");
        std::fs::write(
            &scene,
            "[[systems]]\nshape = { type = \"mesh\", path = \"no.ply\" }\n",
        )
        .expect("scene");
        let err = read_scene_file(&scene).expect_err("missing");
        assert!(err.to_string().contains("systems[0].shape.path"), "{err}");

        // A scene without meshes is sent as written, comments and all.
        let plain = "# a comment\nname = \"p\"\n";
        assert_eq!(inline_meshes(plain, &dir).expect("plain"), plain);
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
