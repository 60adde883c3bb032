//! The one policy for the files a scene names beside itself (glTF buffer and image URIs,
//! AFF includes and texture names): a reference is a path relative to the scene's folder
//! and must stay inside it.
//!
//! * resolved lexically (`a/../b` is `b` whether or not `a` exists), so the path checked
//!   is the path opened; an absolute path, a Windows prefix, or a `..` above the folder
//!   is refused;
//! * then, when the file exists, through the file system: a symbolic link (of the file or
//!   of a folder on the way) that lands outside the scene's folder is refused too.
//!
//! A refused reference is never opened, so no error can quote a file outside the folder.

use std::path::{Component, Path, PathBuf};

/// Why a reference was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Outside {
    /// An absolute path (or a drive or UNC prefix).
    Absolute,
    /// A `..` that climbs above the scene's folder.
    Above,
    /// A symbolic link that resolves outside the scene's folder.
    Symlink,
}

impl std::fmt::Display for Outside {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Outside::Absolute => "an absolute path",
            Outside::Above => "`..` above the folder",
            Outside::Symlink => "a symbolic link out of the folder",
        })
    }
}

/// `folder` joined with `reference` when the result stays inside `folder` (see the module
/// docs); the path to open.
pub(crate) fn resolve_inside(folder: &Path, reference: &Path) -> Result<PathBuf, Outside> {
    let mut rel = PathBuf::new();
    for c in reference.components() {
        match c {
            Component::Normal(part) => rel.push(part),
            Component::CurDir => {}
            Component::ParentDir => {
                if !rel.pop() {
                    return Err(Outside::Above);
                }
            }
            Component::RootDir | Component::Prefix(_) => return Err(Outside::Absolute),
        }
    }
    let resolved = folder.join(&rel);
    // A file that does not exist (or cannot be resolved) is left to the read, whose error
    // names the lexical path: inside the folder.
    if let Ok(real) = std::fs::canonicalize(&resolved) {
        let base = if folder.as_os_str().is_empty() {
            Path::new(".")
        } else {
            folder
        };
        match std::fs::canonicalize(base) {
            Ok(real_folder) if real.starts_with(&real_folder) => {}
            _ => return Err(Outside::Symlink),
        }
    }
    Ok(resolved)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lexical_rules() {
        let f = Path::new("/nonexistent/scene");
        assert_eq!(
            resolve_inside(f, Path::new("a/../b.bin")),
            Ok(f.join("b.bin"))
        );
        assert_eq!(resolve_inside(f, Path::new("./x/y")), Ok(f.join("x/y")));
        assert_eq!(
            resolve_inside(f, Path::new("/etc/hostname")),
            Err(Outside::Absolute)
        );
        assert_eq!(resolve_inside(f, Path::new("../x")), Err(Outside::Above));
        assert_eq!(
            resolve_inside(f, Path::new("a/../../x")),
            Err(Outside::Above)
        );
    }

    #[cfg(unix)]
    #[test]
    fn symlinks_out_are_refused_and_in_are_followed() {
        let root = std::env::temp_dir().join(format!("subfield-folder-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let scene = root.join("scene");
        std::fs::create_dir_all(scene.join("sub")).unwrap();
        std::fs::write(root.join("secret"), b"x").unwrap();
        std::fs::write(scene.join("sub/inside.txt"), b"y").unwrap();
        std::os::unix::fs::symlink(root.join("secret"), scene.join("out")).unwrap();
        std::os::unix::fs::symlink(&root, scene.join("up")).unwrap();
        std::os::unix::fs::symlink(scene.join("sub/inside.txt"), scene.join("in")).unwrap();
        assert_eq!(
            resolve_inside(&scene, Path::new("out")),
            Err(Outside::Symlink)
        );
        assert_eq!(
            resolve_inside(&scene, Path::new("up/secret")),
            Err(Outside::Symlink)
        );
        assert_eq!(
            resolve_inside(&scene, Path::new("in")),
            Ok(scene.join("in"))
        );
        assert_eq!(
            resolve_inside(&scene, Path::new("missing")),
            Ok(scene.join("missing"))
        );
        std::fs::remove_dir_all(&root).unwrap();
    }
}
