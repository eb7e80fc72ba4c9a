//! Where a scene's meshes come from, and the policy that keeps a host's
//! files out of reach of the scenes it is sent.
//!
//! A mesh shape carries its file's bytes ([`MeshData`]) or names a file by
//! `path`. [`Scene::check`](super::Scene::check) loads every named file
//! once, under the host's [`MeshFiles`] policy, into its `data`; from then
//! on shapes are made from bytes only, so nothing after admission touches
//! the file system. A program reading its own scenes allows any file
//! ([`MeshFiles::Host`], the default); a server allows only a directory it
//! was given, or no file at all, so a client can neither read a host file
//! nor learn whether one exists.

use super::SceneError;
use crate::geometry::read::{MeshFormat, quote, read_regular_file};
use serde::{Deserialize, Serialize};
use std::path::{Component, Path, PathBuf};

/// Which mesh files a scene may name by path.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum MeshFiles {
    /// Any file this process can read, relative paths from its working
    /// directory: a program reading scenes its own user wrote.
    #[default]
    Host,
    /// Only regular files inside this directory, named by relative paths
    /// without `..`; a link that leads out of it is refused. Errors never
    /// tell a missing file from an unreadable one, nor show where the
    /// directory is.
    Directory(PathBuf),
    /// No file: every mesh travels in the scene (`data`).
    None,
}

/// A mesh file's bytes, carried in the scene itself: what a client sends
/// a server that reads no client-named files. In a TOML scene the bytes
/// are Base64 text: `data = { format = "obj", base64 = "..." }`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshData {
    /// How to read `content`.
    pub format: MeshFormat,
    /// The file's bytes.
    #[serde(rename = "base64", with = "base64_text")]
    pub content: Vec<u8>,
}

/// Base64 (standard alphabet, padded) for bytes in a text format.
mod base64_text {
    use base64::Engine as _;
    use base64::engine::general_purpose::STANDARD;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(bytes: &[u8], serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&STANDARD.encode(bytes))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<u8>, D::Error> {
        let text = String::deserialize(deserializer)?;
        STANDARD
            .decode(text.trim())
            .map_err(|e| serde::de::Error::custom(format!("mesh data is not Base64 text ({e})")))
    }
}

/// Default of [`super::BuildOptions::max_mesh_bytes`].
pub const DEFAULT_MAX_MESH_BYTES: u64 = 256 << 20;

/// Loads the file a mesh shape names into its data, under `files`; a
/// shape that already carries data is left as it is. `at` is the shape's
/// field (`systems[2].shape`), which errors name.
///
/// # Errors
/// [`SceneError::Invalid`] naming `{at}.path` or `{at}.data`: no path and
/// no data, a path the policy refuses or that names no readable regular
/// file of at most `max_bytes`, or data over `max_bytes`.
pub(crate) fn load(
    path: Option<&str>,
    data: &mut Option<MeshData>,
    files: &MeshFiles,
    max_bytes: u64,
    at: &str,
) -> Result<(), SceneError> {
    if let Some(data) = data {
        let bytes = data.content.len() as u64;
        if bytes > max_bytes {
            return Err(SceneError::invalid(
                format!("{at}.data"),
                format!(
                    "is {bytes} bytes, over this host's limit of {max_bytes}; simplify the mesh"
                ),
            ));
        }
        return Ok(());
    }
    let field = format!("{at}.path");
    let path = match path {
        Some(p) if !p.is_empty() => p,
        _ => {
            return Err(SceneError::invalid(
                field,
                "is empty; name an OBJ or PLY file, or send the mesh's bytes in `data`",
            ));
        }
    };
    let file = Path::new(path);
    // The path is the client's: quoted short, not echoed whole as the
    // reader's own error does (found by the `requests` fuzz target).
    let format = MeshFormat::of_path(file).map_err(|_| {
        SceneError::invalid(
            &field,
            format!(
                "is {}, not an .obj or .ply file; name one, or send the mesh's bytes in `data`",
                quote(path)
            ),
        )
    })?;
    let content = match files {
        MeshFiles::Host => read_regular_file(file, max_bytes).map_err(|e| {
            let tried = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
            SceneError::invalid(
                &field,
                format!("cannot load the mesh (tried {}): {e}", tried.display()),
            )
        })?,
        MeshFiles::Directory(directory) => read_inside(directory, file, max_bytes, &field)?,
        MeshFiles::None => {
            return Err(SceneError::invalid(
                field,
                "this host reads no mesh files; send the mesh's bytes in `data` \
                 (`meshless session create` does so for the files a scene names)",
            ));
        }
    };
    *data = Some(MeshData { format, content });
    Ok(())
}

/// The bytes of `file`, a relative path inside `directory`.
fn read_inside(
    directory: &Path,
    file: &Path,
    max_bytes: u64,
    field: &str,
) -> Result<Vec<u8>, SceneError> {
    let relative = file
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    if !relative {
        return Err(SceneError::invalid(
            field,
            "must be a path relative to the server's mesh directory, without `..`; \
             or send the mesh's bytes in `data`",
        ));
    }
    // One message for every way a file can fail to be there, so that a
    // client learns nothing about the host beyond the directory's files.
    let absent = || {
        SceneError::invalid(
            field,
            "names no readable mesh file in the server's mesh directory; list the \
             meshes it offers with its operator, or send the mesh's bytes in `data`",
        )
    };
    let root = directory.canonicalize().map_err(|_| absent())?;
    let target = root.join(file).canonicalize().map_err(|_| absent())?;
    if !target.starts_with(&root) {
        return Err(absent());
    }
    read_regular_file(&target, max_bytes).map_err(|e| match e.kind() {
        std::io::ErrorKind::FileTooLarge => SceneError::invalid(
            field,
            format!("is larger than this host's limit of {max_bytes} bytes"),
        ),
        _ => absent(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

    /// A mesh directory with one mesh, a link out of it and a FIFO, and a
    /// file outside it.
    struct Fixture {
        root: PathBuf,
    }

    impl Fixture {
        fn new(name: &str) -> Self {
            let root =
                std::env::temp_dir().join(format!("meshless-mesh-{name}-{}", std::process::id()));
            let meshes = root.join("meshes");
            std::fs::create_dir_all(meshes.join("sub")).expect("dirs");
            std::fs::write(meshes.join("sub/tetra.obj"), TETRA).expect("mesh");
            std::fs::write(root.join("secret.obj"), TETRA).expect("outside");
            #[cfg(unix)]
            {
                std::os::unix::fs::symlink(root.join("secret.obj"), meshes.join("out.obj"))
                    .expect("link");
                std::os::unix::fs::symlink("/dev/zero", meshes.join("zero.obj")).expect("link");
                let fifo = meshes.join("fifo.obj");
                let made = std::process::Command::new("mkfifo").arg(&fifo).status();
                assert!(made.is_ok_and(|s| s.success()), "mkfifo");
            }
            Self { root }
        }

        fn files(&self) -> MeshFiles {
            MeshFiles::Directory(self.root.join("meshes"))
        }
    }

    impl Drop for Fixture {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.root);
        }
    }

    fn load_path(path: &str, files: &MeshFiles) -> Result<MeshData, SceneError> {
        let mut data = None;
        load(Some(path), &mut data, files, 1 << 20, "systems[1].shape")?;
        Ok(data.expect("loaded"))
    }

    #[test]
    fn a_directory_gives_its_own_files_and_nothing_else() {
        let fixture = Fixture::new("directory");
        let files = fixture.files();
        let data = load_path("sub/tetra.obj", &files).expect("inside");
        assert_eq!(data.format, MeshFormat::Obj);
        assert_eq!(data.content, TETRA.as_bytes());
        assert!(load_path("./sub/tetra.obj", &files).is_ok());

        let secret = fixture.root.join("secret.obj");
        let refused = [
            secret.to_str().expect("utf-8").to_owned(),
            "../secret.obj".into(),
            "sub/../../secret.obj".into(),
            "out.obj".into(),
            "zero.obj".into(),
            "fifo.obj".into(),
            "missing.obj".into(),
            "sub".into(),
        ];
        let root = fixture.root.to_str().expect("utf-8");
        for path in &refused {
            let err = load_path(path, &files).expect_err(path);
            let message = err.to_string();
            assert!(
                message.starts_with("systems[1].shape.path"),
                "{path}: {message}"
            );
            assert!(
                !message.contains(root),
                "{path} disclosed the directory: {message}"
            );
        }
        // A missing file and a link out read the same: nothing disclosed.
        let missing = load_path("missing.obj", &files).expect_err("missing");
        let link = load_path("out.obj", &files).expect_err("link");
        let fifo = load_path("fifo.obj", &files).expect_err("fifo");
        assert_eq!(missing.to_string(), link.to_string());
        assert_eq!(missing.to_string(), fifo.to_string());
    }

    #[test]
    fn no_files_at_all_and_size_limits() {
        let fixture = Fixture::new("none");
        let err = load_path("sub/tetra.obj", &MeshFiles::None).expect_err("no files");
        assert!(err.to_string().contains("`data`"), "{err}");

        let mut data = None;
        let err = load(Some("sub/tetra.obj"), &mut data, &fixture.files(), 10, "s")
            .expect_err("over the limit");
        assert!(err.to_string().contains("limit of 10 bytes"), "{err}");

        let mut data = Some(MeshData {
            format: MeshFormat::Ply,
            content: vec![0; 11],
        });
        let err = load(None, &mut data, &MeshFiles::None, 10, "s").expect_err("inline over");
        assert!(err.to_string().starts_with("s.data"), "{err}");
        data.as_mut().expect("data").content.truncate(10);
        load(None, &mut data, &MeshFiles::None, 10, "s").expect("inline within the limit");

        let err = load(None, &mut None, &MeshFiles::Host, 10, "s").expect_err("nothing");
        assert!(err.to_string().starts_with("s.path: is empty"), "{err}");
    }

    /// A path that names no mesh format is quoted short, not echoed
    /// whole (`fuzz/regressions/requests` holds the obstacle edit that
    /// found it, its path a whole OBJ file).
    #[test]
    fn a_path_without_a_mesh_extension_is_quoted_short() {
        let long = "v 0 0 0\n".repeat(100);
        let err = load_path(&long, &MeshFiles::None).expect_err("no extension");
        let message = err.to_string();
        assert!(
            message.starts_with("systems[1].shape.path: is \"v 0 0 0\\n"),
            "{message}"
        );
        assert!(message.contains(".obj or .ply"), "{message}");
        assert!(message.len() < 200, "{message}");
    }

    #[test]
    fn the_host_policy_reads_any_regular_file_but_no_device() {
        let fixture = Fixture::new("host");
        let secret = fixture.root.join("secret.obj");
        let data = load_path(secret.to_str().expect("utf-8"), &MeshFiles::Host).expect("host");
        assert_eq!(data.content, TETRA.as_bytes());
        let zero = fixture.root.join("meshes/zero.obj");
        let err = load_path(zero.to_str().expect("utf-8"), &MeshFiles::Host).expect_err("device");
        assert!(err.to_string().contains("regular file"), "{err}");
    }

    #[test]
    fn inline_data_round_trips_through_toml_as_base64() {
        #[derive(Serialize, Deserialize)]
        struct Holder {
            data: MeshData,
        }
        let holder = Holder {
            data: MeshData {
                format: MeshFormat::Ply,
                content: vec![0, 1, 2, 255],
            },
        };
        let text = toml::to_string(&holder).expect("serialise");
        assert!(text.contains("base64 = \"AAEC/w==\""), "{text}");
        let back: Holder = toml::from_str(&text).expect("parse");
        assert_eq!(back.data, holder.data);
        let err = toml::from_str::<Holder>("data = { format = \"obj\", base64 = \"*\" }")
            .err()
            .expect("not base64");
        assert!(err.to_string().contains("not Base64"), "{err}");
    }
}
