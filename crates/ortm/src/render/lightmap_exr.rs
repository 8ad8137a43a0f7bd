//! Lightmaps as linear OpenEXR files (`--lightmap-out`, `--first-order-out`).
//!
//! [`write_lightmap_exr`] writes a single-part scan-line OpenEXR file, channels `R`, `G`, `B`
//! as 32-bit floats (lossless; values are radiosity `B` in W/m², linear RGB), data window =
//! display window = the whole `W×H` lightmap, row 0 first (row 0 is `v = 1`). It is written
//! atomically ([`crate::io::write_atomic`]), so a crash never leaves a half-written file under
//! the final name. [`read_lightmap_exr`] reads such a file back (any
//! RGB(A) OpenEXR image, first layer).

use std::path::Path;

use super::RenderError;
use crate::Lightmap;

/// Writes `map` as a linear RGB f32 OpenEXR file (see the module docs), atomically
/// ([`crate::io::write_atomic`]).
pub fn write_lightmap_exr(path: &Path, map: &Lightmap) -> Result<(), RenderError> {
    let (w, h) = (map.width as usize, map.height as usize);
    if map.data.len() != w * h || w == 0 || h == 0 {
        return Err(RenderError::LightmapLength {
            path: path.to_owned(),
            width: map.width,
            height: map.height,
            len: map.data.len(),
        });
    }
    let exr_err = |source| RenderError::Exr {
        op: "write",
        path: path.to_owned(),
        source,
    };
    let channels =
        exr::prelude::SpecificChannels::rgb(|exr::math::Vec2(x, y): exr::math::Vec2<usize>| {
            let v = map.data[y * w + x];
            (v[0], v[1], v[2])
        });
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr::prelude::WritableImage::write(&exr::prelude::Image::from_channels((w, h), channels))
        .to_buffered(&mut bytes)
        .map_err(exr_err)?;
    crate::io::write_atomic(path, bytes.get_ref()).map_err(|e| exr_err(e.into()))
}

/// Reads the first RGB(A) layer of an OpenEXR file as a lightmap (alpha ignored; a missing
/// alpha channel is fine).
pub fn read_lightmap_exr(path: &Path) -> Result<Lightmap, RenderError> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |size, _| Lightmap::new(size.0 as u32, size.1 as u32),
        |map: &mut Lightmap, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            map.set(pos.0 as u32, pos.1 as u32, [r, g, b]);
        },
    )
    .map_err(|source| RenderError::Exr {
        op: "read",
        path: path.to_owned(),
        source,
    })?;
    Ok(image.layer_data.channel_data.pixels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_lightmap_round_trip_is_exact_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = Lightmap::new(7, 5);
        for (i, v) in m.data.iter_mut().enumerate() {
            let f = i as f32;
            *v = [f * 1.25e-3, -f, 1e-7 * f + 3.0];
        }
        let p = dir.path().join("final.exr");
        write_lightmap_exr(&p, &m).unwrap();
        assert_eq!(read_lightmap_exr(&p).unwrap(), m);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("final.exr")]);
        // Malformed input and missing folders are errors, not panics.
        let bad = Lightmap {
            width: 3,
            height: 3,
            data: vec![[0.0; 3]; 4],
        };
        assert!(matches!(
            write_lightmap_exr(&p, &bad),
            Err(RenderError::LightmapLength { .. })
        ));
        assert!(write_lightmap_exr(&dir.path().join("no/such/dir/x.exr"), &m).is_err());
        assert!(read_lightmap_exr(&dir.path().join("missing.exr")).is_err());
    }
}
