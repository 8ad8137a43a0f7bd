//! Glue between a bake and the real-time renderer (the `passes` crate): open a bake for
//! rendering, convert ortm's types into `passes::types`, pick cameras and exposure, and read
//! and write lightmaps as linear OpenEXR files.
//!
//! # Files
//! - [`open`]: a bake directory's atlases (`atlases.json`, or packed from the maps) and the
//!   scene it was made from, checked against the bake's scene hash.
//! - [`convert`]: mesh, albedo, lights, atlases → `passes` inputs; read-back → [`crate::Lightmap`].
//! - [`camera`]: the default camera, `--camera` and `--size`.
//! - [`exposure`]: automatic exposure and `--exposure`.
//! - [`lightmap_exr`]: lightmap OpenEXR files.
//!
//! A light's text form (`--light`) lives with the light: [`crate::scene::light`].
//!
//! # Data flow
//! ```text
//! bake dir ──open_bake──▶ AtlasSet + Scene ──convert──▶ MeshData, AlbedoMap, LightDesc,
//!     AtlasData + TransferPiece ──▶ passes::Renderer ──▶ TexelImage ──to_lightmap──▶ Lightmap
//!     ──write_lightmap_exr──▶ .exr;   camera + exposure ──▶ the displayed frame
//! ```
//!
//! # Units and conventions
//! Everything is SI, as in the rest of ortm: positions in metres, point/spot intensity in
//! W/sr, directional irradiance in W/m², lightmaps in radiosity `B = π·L_out` (W/m², linear
//! RGB). Lightmap texel `(x, y)` has its centre at `u = (x+0.5)/W`, `v = 1 − (y+0.5)/H`
//! (row 0 is `v = 1`), identical in `ortm` and `passes`, so no flips happen here. Transfer
//! pieces keep the bake's offset convention (`Δt = (dx, dy)` in texels, `+dy` down).
//!
//! # Limits
//! The first-order pass uses shadow maps; [`shadow_layers_for`] sizes the layer array
//! (6 per point light, 1 per spot or directional light).

pub mod camera;
pub mod convert;
pub mod exposure;
pub mod lightmap_exr;
pub mod open;

use std::path::PathBuf;

use passes::PassError;

use crate::atlas::{ATLAS_INDEX_FILE_NAME, AtlasError};
use crate::bake_dir::INDEX_FILE_NAME;
use crate::maps::MapsError;
use crate::scene::light::SpecError;

pub use camera::{CAMERA_SYNTAX, SIZE_SYNTAX, default_camera, parse_camera, parse_size};
pub use convert::{
    albedo_map, diffusion_lengths, light_desc, mesh_data, shadow_layers_for, texel_weights,
    to_lightmap, transfer_inputs, transfer_piece,
};
pub use exposure::{auto_exposure, parse_exposure};
pub use lightmap_exr::{read_lightmap_exr, write_lightmap_exr};
pub use open::{
    AtlasSource, BakeAndScene, DEFAULT_ATLAS_SIDE, check_scene, effects_of, load_bake_atlases,
    open_bake, scene_arg_from_settings,
};

/// Everything that can go wrong in the render glue.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A GPU pass failed (no adapter, device lost, invalid input, …); the message says why.
    #[error(transparent)]
    Pass(#[from] PassError),
    /// A `--light`, `--camera` or `--size` value could not be parsed.
    #[error(transparent)]
    BadSpec(#[from] SpecError),
    /// An `--exposure` value is neither `auto` nor a positive number.
    #[error("--exposure {spec:?}: use `auto` or a positive number")]
    BadExposure {
        /// The text given.
        spec: String,
    },
    /// The atlas set is inconsistent (atlas data length, piece outside its atlas or the
    /// lightmap, lightmap size differing from the scene's).
    #[error("atlas set: {problem}; rebuild the atlases with `ortm bin` from this bake")]
    BadAtlas {
        /// What is wrong (names the atlas or piece).
        problem: String,
    },
    /// A lightmap handed to the EXR writer holds the wrong number of texels.
    #[error(
        "lightmap for {}: {width}×{height} but holds {len} texels; build it with Lightmap::new",
        path.display()
    )]
    LightmapLength {
        /// Destination file.
        path: PathBuf,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// Actual data length.
        len: usize,
    },
    /// Writing or reading an OpenEXR lightmap failed.
    #[error(
        "cannot {op} OpenEXR lightmap {}: {source}; check the path (folder exists, writable, \
         enough space) or that the file is a complete RGB OpenEXR image",
        path.display()
    )]
    Exr {
        /// `write` or `read`.
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The codec's error.
        #[source]
        source: exr::error::Error,
    },
    /// The bake's maps or index could not be read.
    #[error(transparent)]
    Maps(#[from] MapsError),
    /// The atlases could not be built or read.
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    /// The folder is not a bake directory.
    #[error(
        "{} is not a bake directory: it has neither {INDEX_FILE_NAME} nor {ATLAS_INDEX_FILE_NAME}; \
         pass the folder written by `ortm bake` (and optionally `ortm bin`)",
        dir.display()
    )]
    NotABake {
        /// The folder given.
        dir: PathBuf,
    },
    /// A bake directory could not be read (its index or atlases).
    #[error("reading bake directory '{}'", dir.display())]
    ReadBake {
        /// The bake folder.
        dir: PathBuf,
        /// What went wrong.
        #[source]
        source: Box<RenderError>,
    },
    /// No scene was given and the bake does not record one.
    #[error(
        "the bake in '{}' does not record which scene it was made from; pass it with \
         --scene (`cornell` or the scene file used for `ortm bake`)",
        dir.display()
    )]
    NoSceneRecorded {
        /// The bake folder.
        dir: PathBuf,
    },
    /// The scene the bake records is not opened without the user naming it
    /// ([`crate::bake_dir::check_recorded_scene`]).
    #[error(
        "the bake in '{}' records the scene '{scene}', which {problem}; a bake directory's \
         index is not trusted to open files outside it: pass the scene with --scene",
        dir.display()
    )]
    UntrustedScene {
        /// The bake folder.
        dir: PathBuf,
        /// The recorded scene argument.
        scene: String,
        /// Why it is not opened.
        problem: String,
    },
    /// The scene given is not the one the bake was made from.
    #[error(
        "the bake in {} was made from a different scene (scene hash {expected}, but `{scene}` \
         at {width}×{height} hashes to {found}); pass the scene file (or `cornell`) used for \
         the bake with --scene",
        dir.display()
    )]
    SceneMismatch {
        /// The bake folder.
        dir: PathBuf,
        /// The scene argument.
        scene: String,
        /// Lightmap width of the bake.
        width: u32,
        /// Lightmap height of the bake.
        height: u32,
        /// Hash stored in the bake index.
        expected: String,
        /// Hash of the scene given.
        found: String,
    },
    /// A file-system operation failed.
    #[error("cannot {op} {}: {source}; check that the folder exists and is writable", path.display())]
    Io {
        /// What was being done.
        op: &'static str,
        /// The path.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
}
