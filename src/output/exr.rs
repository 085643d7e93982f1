//! OpenEXR: lightmap pages (the HDR lightmap a renderer uses) and rendered images.
//!
//! EXR pages hold channels R, G, B of linear `H/π`, half float by default or 32-bit float on
//! request, ZIP-compressed scanlines in increasing order (so the bytes do not depend on how
//! many threads compressed them), row 0 at the top, with `software = lightbake`.
//! Invalid texels (never solved nor dilated) and non-finite values are written as black.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::traits::*;
use exr::prelude::{
    Encoding, Image, IntoSample, Layer, LayerAttributes, SpecificChannels, Text, Vec2 as ExrVec2,
    f16,
};
use glam::Vec3;

use crate::lightmap::Page;
use crate::{Error, Result};

/// Encodes a page as OpenEXR (linear RGB, half or float). `input` names the scene in errors.
pub fn write_exr(page: &Page, float: bool, input: &Path) -> Result<Vec<u8>> {
    let texel = |p: ExrVec2<usize>| {
        let k = p.y() * page.width as usize + p.x();
        if page.valid[k] && page.rgb[k].is_finite() {
            page.rgb[k]
        } else {
            Vec3::ZERO
        }
    };
    let result = if float {
        encode(page, move |p: ExrVec2<usize>| {
            let v = texel(p);
            (v.x, v.y, v.z)
        })
    } else {
        // Clamp to the largest half, or bright texels would turn into infinities.
        let half = |x: f32| f16::from_f32(x.clamp(-f16::MAX.to_f32(), f16::MAX.to_f32()));
        encode(page, move |p: ExrVec2<usize>| {
            let v = texel(p);
            (half(v.x), half(v.y), half(v.z))
        })
    };
    result.map_err(|e| Error::io(input, exr_to_io(e)))
}

fn encode<T, F>(page: &Page, pixels: F) -> exr::error::Result<Vec<u8>>
where
    T: IntoSample,
    F: Sync + Fn(ExrVec2<usize>) -> (T, T, T),
    F: GetPixel<Pixel = (T, T, T)>,
{
    let attributes = LayerAttributes {
        software_name: Some(Text::from("lightbake")),
        ..LayerAttributes::default()
    };
    let layer = Layer::new(
        (page.width as usize, page.height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        SpecificChannels::rgb(pixels),
    );
    let mut bytes = Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut bytes)?;
    Ok(bytes.into_inner())
}

fn exr_to_io(e: exr::error::Error) -> std::io::Error {
    match e {
        exr::error::Error::Io(e) => e,
        other => std::io::Error::other(other.to_string()),
    }
}

/// Reads an EXR page back (round-trip tests, `render`, `--reference`): channels R, G, B of the
/// first layer, every texel valid, non-finite values read as black.
pub fn read_exr(path: &Path) -> Result<Page> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |size, _| (size.width(), vec![Vec3::ZERO; size.width() * size.height()]),
            |(width, rgb): &mut (usize, Vec<Vec3>), p, (r, g, b): (f32, f32, f32)| {
                let v = Vec3::new(r, g, b);
                rgb[p.y() * *width + p.x()] = if v.is_finite() { v } else { Vec3::ZERO };
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| match e {
            exr::error::Error::Io(e) => Error::io(path, e),
            other => Error::invalid(path, format!("not a readable RGB OpenEXR file: {other}")),
        })?;
    let layer = image.layer_data;
    let (width, rgb) = layer.channel_data.pixels;
    let height = layer.size.height();
    Ok(Page {
        width: width as u32,
        height: height as u32,
        valid: vec![true; rgb.len()],
        rgb,
    })
}

/// Writes a rendered image (linear RGB radiance, row-major, row 0 at the top) to `path` as a
/// 32-bit float OpenEXR file (the exr crate's default encoding: RLE, 64 × 64 tiles).
///
/// Tiles are compressed and written one after the other: compressed in parallel, they were
/// written in whatever order they finished, so the same image gave different bytes.
pub fn write_exr_image(path: &Path, rgb: &[Vec3], width: u32, height: u32) -> Result<()> {
    let w = width as usize;
    let pixels = SpecificChannels::rgb(|p: ExrVec2<usize>| {
        let v = rgb[p.y() * w + p.x()];
        (v.x, v.y, v.z)
    });
    Image::from_channels((w, height as usize), pixels)
        .write()
        .non_parallel()
        .to_file(path)
        .map_err(|e| Error::io(path, exr_to_io(e)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::test_page;

    fn round_trip(float: bool) -> Page {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("page.exr");
        std::fs::write(
            &path,
            write_exr(&test_page(), float, Path::new("scene.gltf")).unwrap(),
        )
        .unwrap();
        read_exr(&path).unwrap()
    }

    #[test]
    fn float_exr_round_trips_exactly_with_invalid_texels_black() {
        let page = test_page();
        let back = round_trip(true);
        assert_eq!((back.width, back.height), (3, 2));
        assert!(back.valid.iter().all(|&v| v));
        for k in 0..6 {
            let expected = if page.valid[k] {
                page.rgb[k]
            } else {
                Vec3::ZERO
            };
            assert_eq!(back.rgb[k], expected, "texel {k}");
        }
    }

    #[test]
    fn half_exr_round_trips_within_half_precision() {
        let page = test_page();
        let back = round_trip(false);
        assert_eq!((back.width, back.height), (3, 2));
        for k in 0..6 {
            let expected = if page.valid[k] {
                page.rgb[k]
            } else {
                Vec3::ZERO
            };
            let error = (back.rgb[k] - expected).abs();
            assert!(
                error.cmple(expected * 1e-3 + Vec3::splat(1e-6)).all(),
                "texel {k}: {}",
                back.rgb[k]
            );
        }
        // Exactly representable values survive exactly, in the right place (row 0 = top).
        assert_eq!(back.rgb[0].y, 5.5);
        assert_eq!(back.rgb[0].z, 1000.0);
        assert_eq!(back.rgb[4], Vec3::new(0.75, 0.0625, 42.0));
    }

    #[test]
    fn half_exr_clamps_instead_of_overflowing() {
        let page = Page {
            width: 1,
            height: 1,
            rgb: vec![Vec3::splat(1.0e6)],
            valid: vec![true],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bright.exr");
        std::fs::write(
            &path,
            write_exr(&page, false, Path::new("in.gltf")).unwrap(),
        )
        .unwrap();
        assert_eq!(read_exr(&path).unwrap().rgb[0], Vec3::splat(65504.0));
    }

    #[test]
    fn exr_bytes_are_deterministic_and_carry_the_software_name() {
        let a = write_exr(&test_page(), false, Path::new("a.gltf")).unwrap();
        let b = write_exr(&test_page(), false, Path::new("a.gltf")).unwrap();
        assert_eq!(a, b);
        assert!(a.windows(9).any(|w| w == b"lightbake"));
    }

    #[test]
    fn rendered_images_read_back_exactly_and_give_the_same_bytes_every_time() {
        // 300 × 200 pixels: 5 × 4 tiles, enough for parallel compression to reorder them.
        let (width, height) = (300, 200);
        let rgb: Vec<Vec3> = (0..width * height)
            .map(|i| Vec3::new(i as f32, (i % 7) as f32 * 0.25, 1.0 / (1 + i) as f32))
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str| {
            let path = dir.path().join(name);
            write_exr_image(&path, &rgb, width, height).unwrap();
            path
        };
        let first = write("a.exr");
        let back = read_exr(&first).unwrap();
        assert_eq!((back.width, back.height), (width, height));
        assert_eq!(back.rgb, rgb);
        let bytes = std::fs::read(&first).unwrap();
        for k in 0..16 {
            let again = std::fs::read(write(&format!("{k}.exr"))).unwrap();
            assert!(again == bytes, "write {k} gave other bytes");
        }
    }

    #[test]
    fn read_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.exr");
        assert!(
            read_exr(&missing)
                .unwrap_err()
                .to_string()
                .contains("missing.exr")
        );
        let garbage = dir.path().join("garbage.exr");
        std::fs::write(&garbage, b"this is not an exr file").unwrap();
        let error = read_exr(&garbage).unwrap_err();
        assert!(matches!(error, Error::Invalid { .. }), "{error}");
        assert!(error.to_string().contains("garbage.exr"));
    }
}
