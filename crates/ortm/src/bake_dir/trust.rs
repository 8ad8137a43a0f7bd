//! What a bake directory may make the reader open on its own: the scene its `index.json`
//! records (`settings.scene`). The directory is untrusted input, so the recorded scene is
//! opened only when it names nothing on disk (a built-in scene name such as `cornell`, or a
//! missing file the scene loader reports) or resolves, after following symbolic links, to a
//! path inside the bake directory's own tree. Anything else needs the user to name it
//! (`--scene`).

use std::path::Path;

/// Checks that the recorded scene argument `scene` of the bake in `dir` may be opened without
/// the user naming it (module docs). The argument is read as the scene loader reads it: a
/// built-in name, or a path relative to the working directory.
///
/// # Errors
/// Why not, as words for a message: "resolves to P, outside the bake directory D", or what
/// the path is when it cannot be resolved (a symbolic link loop, a dangling link).
pub fn check_recorded_scene(dir: &Path, scene: &str) -> Result<(), String> {
    let path = Path::new(scene);
    if std::fs::symlink_metadata(path).is_err() {
        // Nothing on disk: a built-in name, or a file the loader will say does not exist.
        return Ok(());
    }
    let real = std::fs::canonicalize(path).map_err(|_| {
        crate::io::not_a_regular_file(path).unwrap_or_else(|| "cannot be resolved".into())
    })?;
    let real_dir = std::fs::canonicalize(dir).map_err(|e| {
        format!(
            "the bake directory {} cannot be resolved: {e}",
            dir.display()
        )
    })?;
    if real.starts_with(&real_dir) {
        Ok(())
    } else {
        Err(format!(
            "resolves to {}, outside the bake directory {}",
            real.display(),
            real_dir.display()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_scenes_inside_the_bake_or_nowhere_on_disk() {
        let root = tempfile::tempdir().unwrap();
        let bake = root.path().join("bake");
        std::fs::create_dir_all(bake.join("sub")).unwrap();
        let inside = bake.join("sub/scene.toml");
        let outside = root.path().join("scene.toml");
        std::fs::write(&inside, "").unwrap();
        std::fs::write(&outside, "").unwrap();
        assert_eq!(
            check_recorded_scene(&bake, inside.to_str().unwrap()),
            Ok(())
        );
        let e = check_recorded_scene(&bake, outside.to_str().unwrap()).unwrap_err();
        assert!(e.contains("outside the bake directory"), "{e}");
        // A link inside the bake pointing out is judged by where it leads.
        let link = bake.join("link.toml");
        std::os::unix::fs::symlink(&outside, &link).unwrap();
        assert!(check_recorded_scene(&bake, link.to_str().unwrap()).is_err());
        let missing = root.path().join("missing.toml");
        assert_eq!(
            check_recorded_scene(&bake, missing.to_str().unwrap()),
            Ok(())
        );
    }
}
