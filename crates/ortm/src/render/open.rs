//! Opening a bake directory for rendering: its `index.json` (from `ortm bake`), its atlases
//! (`atlases.json` from `ortm bin`, or packed in memory from the transfer maps when the bake
//! was not binned) and the scene it was made from, checked against the bake's scene hash.
//!
//! # Data flow
//! ```text
//! DIR/index.json ─────────────┐
//! DIR/atlases.json + atlases ─┴─load_bake_atlases──▶ (BakeIndex?, AtlasSet, AtlasSource)
//! --scene, else the bake's settings.scene ──load_scene──▶ Scene ──check_scene──▶ BakeAndScene
//! ```
//! The scene is loaded at the bake's lightmap size (texels); atlas sides are in texels.

use std::path::Path;

use super::RenderError;
use crate::atlas::{ATLAS_INDEX_FILE_NAME, AtlasSet};
use crate::bake::transport::Effects;
use crate::bake_dir::{BakeIndex, INDEX_FILE_NAME};
use crate::scene::Scene;

/// Where [`load_bake_atlases`] got the atlases from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AtlasSource {
    /// `atlases.json` and its atlas files (written by `ortm bin`).
    Files,
    /// Packed in memory from the bake's transfer maps.
    PackedFromMaps,
}

/// Atlas side used when a bake has no `atlases.json` (the paper's 1024²).
pub const DEFAULT_ATLAS_SIDE: u32 = 1024;

/// Reads a bake directory for rendering: its `index.json` (if present) and its atlases —
/// from `atlases.json` when `ortm bin` wrote one (checked against the bake key), otherwise
/// packed in memory from the transfer maps at `atlas_side`² (the maps' sizes and checksums
/// are verified on load).
pub fn load_bake_atlases(
    dir: &Path,
    atlas_side: u32,
) -> Result<(Option<BakeIndex>, AtlasSet, AtlasSource), RenderError> {
    // Anything at the name counts (a FIFO or directory there is then refused by its reader).
    let has_index = std::fs::symlink_metadata(dir.join(INDEX_FILE_NAME)).is_ok();
    let has_atlases = std::fs::symlink_metadata(dir.join(ATLAS_INDEX_FILE_NAME)).is_ok();
    if !has_index && !has_atlases {
        return Err(RenderError::NotABake {
            dir: dir.to_owned(),
        });
    }
    let index = if has_index {
        Some(BakeIndex::read(dir)?)
    } else {
        None
    };
    if has_atlases {
        return Ok((
            index,
            crate::atlas::read_atlas_set(dir)?,
            AtlasSource::Files,
        ));
    }
    let index = index.ok_or_else(|| RenderError::NotABake {
        dir: dir.to_owned(),
    })?;
    let maps = index.load_maps(dir)?;
    let set = crate::atlas::build_atlas_set(&maps, atlas_side, atlas_side)?;
    Ok((Some(index), set, AtlasSource::PackedFromMaps))
}

/// The scene argument stored in a bake's settings (`settings.scene`, a string), if the bake
/// recorded one.
pub fn scene_arg_from_settings(index: &BakeIndex) -> Option<String> {
    index
        .settings
        .get("scene")
        .and_then(|v| v.as_str())
        .map(str::to_owned)
}

/// Checks that `scene` (named `scene_arg` in messages) hashes to the bake's `scene_hash`
/// ([`crate::scene::scene_hash`]: geometry, UVs, normals, materials; not the lights).
pub fn check_scene(
    dir: &Path,
    index: &BakeIndex,
    scene: &Scene,
    scene_arg: &str,
) -> Result<(), RenderError> {
    let found = crate::scene::scene_hash(scene);
    if found != index.scene_hash {
        return Err(RenderError::SceneMismatch {
            dir: dir.to_owned(),
            scene: scene_arg.to_owned(),
            width: index.lightmap.width,
            height: index.lightmap.height,
            expected: index.scene_hash.clone(),
            found,
        });
    }
    Ok(())
}

/// A bake directory opened for rendering ([`open_bake`]): its atlases and the checked scene.
pub struct BakeAndScene {
    /// The bake index, when the directory has one.
    pub index: Option<BakeIndex>,
    /// The atlases.
    pub set: AtlasSet,
    /// Where the atlases came from.
    pub source: AtlasSource,
    /// The scene at the bake's lightmap size.
    pub scene: Scene,
}

impl BakeAndScene {
    /// The effects the bake's maps hold ([`effects_of`]).
    pub fn effects(&self) -> Effects {
        effects_of(self.index.as_ref())
    }
}

/// The effects a bake's maps hold, from its settings (`settings.effects`); all of them for a
/// bake without an index or settings that do not record them. A renderer needs them: a
/// subsurface material's texels are translucent (their first order the scattered average,
/// their light diffused on screen) only when the maps hold the subsurface term.
pub fn effects_of(index: Option<&BakeIndex>) -> Effects {
    let recorded = index.and_then(|ix| ix.settings.get("effects"));
    let flag = |name: &str| {
        recorded
            .and_then(|e| e.get(name))
            .and_then(|v| v.as_bool())
            .unwrap_or(true)
    };
    Effects {
        radiosity: flag("radiosity"),
        subsurface: flag("subsurface"),
    }
}

/// Opens a bake directory for `ortm render` and `ortm view`: its atlases
/// ([`load_bake_atlases`] at `atlas_side`² when it has no `atlases.json`) and its scene —
/// `scene` when given, else the one the bake's settings record — loaded by `load_scene`
/// (scene argument, square lightmap side when the bake's lightmap is square), set to the
/// bake's lightmap size and checked against the bake's scene hash ([`check_scene`]).
pub fn open_bake<E: From<RenderError>>(
    dir: &Path,
    scene: Option<&str>,
    atlas_side: u32,
    load_scene: impl FnOnce(&str, Option<u32>) -> Result<Scene, E>,
) -> Result<BakeAndScene, E> {
    let (index, set, source) =
        load_bake_atlases(dir, atlas_side).map_err(|source| RenderError::ReadBake {
            dir: dir.to_owned(),
            source: Box::new(source),
        })?;
    let scene_arg = match (scene, index.as_ref().and_then(scene_arg_from_settings)) {
        (Some(s), _) => s.to_owned(),
        (None, Some(s)) => {
            crate::bake_dir::check_recorded_scene(dir, &s).map_err(|problem| {
                RenderError::UntrustedScene {
                    dir: dir.to_owned(),
                    scene: s.clone(),
                    problem,
                }
            })?;
            s
        }
        (None, None) => {
            return Err(RenderError::NoSceneRecorded {
                dir: dir.to_owned(),
            }
            .into());
        }
    };
    let (w, h) = set.lightmap_size;
    let mut scene = load_scene(&scene_arg, (w == h).then_some(w))?;
    scene.lightmap_size = (w, h);
    if let Some(index) = &index {
        check_scene(dir, index, &scene, &scene_arg)?;
    }
    Ok(BakeAndScene {
        index,
        set,
        source,
        scene,
    })
}
