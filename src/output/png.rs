//! PNG, the one place lightbake encodes it: 8-bit sRGB pictures for eyes (lightmap page
//! previews, rendered images) and linear RGBM pages for engines without HDR textures.
//!
//! | picture | tone mapping | writer |
//! |---|---|---|
//! | lightmap page preview | `2^exposure`, clip to [0, 1], sRGB | `write_png_preview` |
//! | rendered image | `2^exposure`, [`tone_map`] (identity, then a soft shoulder), sRGB | `write_png_image` |
//! | RGBM page | none: linear RGBM (see [`super::rgbm`]) | `write_rgbm_png` |
//!
//! Previews clip rather than compress highlights so that a lightmap value of 0.5 looks like
//! 0.5; rendered images roll off above `SHOULDER` so highlights keep some detail.

use glam::Vec3;
use image::{ExtendedColorType, ImageEncoder};

use super::rgbm;
use crate::lightmap::Page;
use crate::{Error, Result};

/// Encodes an 8-bit sRGB PNG preview of a page.
///
/// Tone mapping is deliberately plain: scale by `2^exposure`, clip to [0, 1], apply the sRGB
/// transfer function. Unlike Reinhard `x/(1+x)` it keeps mid-tones true (a lightmap value of
/// 0.5 looks like 0.5), at the cost of clipping highlights — lower the exposure to see them.
/// Invalid texels (never solved nor dilated) are black.
pub(crate) fn write_png_preview(page: &Page, exposure: f32) -> Result<Vec<u8>> {
    let scale = exposure.exp2();
    let mut srgb = Vec::with_capacity(page.rgb.len() * 3);
    for (v, &valid) in page.rgb.iter().zip(&page.valid) {
        let v = if valid { *v * scale } else { Vec3::ZERO };
        srgb.extend(v.to_array().map(encode_srgb));
    }
    encode(
        &srgb,
        page.width,
        page.height,
        ExtendedColorType::Rgb8,
        "<png preview>",
    )
}

/// Encodes a rendered image (linear RGB radiance, row-major, row 0 at the top) as an 8-bit sRGB
/// PNG: scale by `2^exposure`, [`tone_map`], then the sRGB transfer function.
pub(crate) fn write_png_image(
    rgb: &[Vec3],
    width: u32,
    height: u32,
    exposure: f32,
) -> Result<Vec<u8>> {
    let scale = exposure.exp2();
    let bytes: Vec<u8> = rgb
        .iter()
        .flat_map(|v| (*v * scale).to_array().map(|c| encode_srgb(tone_map(c))))
        .collect();
    encode(&bytes, width, height, ExtendedColorType::Rgb8, "<png>")
}

/// Encodes a page as an RGBM PNG (8-bit RGBA, linear, see [`super::rgbm`]).
pub(crate) fn write_rgbm_png(page: &Page, range: f32) -> Result<Vec<u8>> {
    let rgba = rgbm::encode(page, range);
    encode(
        &rgba,
        page.width,
        page.height,
        ExtendedColorType::Rgba8,
        "<rgbm png>",
    )
}

/// Where the tone curve of rendered images leaves the identity.
pub(crate) const SHOULDER: f32 = 0.8;

/// Identity up to `SHOULDER`, then `k + (1−k)(1 − e^{−(x−k)/(1−k)})` → 1 (C¹ at `k`):
/// mid-tones stay true and highlights keep some detail instead of clipping. NaN → 0.
pub fn tone_map(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        0.0
    } else if x <= SHOULDER {
        x
    } else {
        let k = SHOULDER;
        k + (1.0 - k) * (1.0 - (-(x - k) / (1.0 - k)).exp())
    }
}

/// Linear value → 8-bit sRGB, clipped to [0, 1] (NaN → 0).
pub fn encode_srgb(linear: f32) -> u8 {
    let x = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    let encoded = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}

/// The PNG encoder every writer above goes through; `what` names the picture in errors.
fn encode(
    pixels: &[u8],
    width: u32,
    height: u32,
    color: ExtendedColorType,
    what: &str,
) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(pixels, width, height, color)
        .map_err(|e| Error::io(what, std::io::Error::other(e.to_string())))?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_preview_has_the_page_size_and_srgb_values() {
        let page = Page {
            width: 4,
            height: 2,
            rgb: vec![
                Vec3::new(1.0, 0.0, 0.5),
                Vec3::splat(0.25),
                Vec3::splat(8.0),
                Vec3::splat(-1.0),
                Vec3::splat(0.5),
                Vec3::splat(0.5),
                Vec3::splat(0.5),
                Vec3::splat(0.5),
            ],
            valid: vec![true, true, true, true, true, false, true, true],
        };
        let png = write_png_preview(&page, 1.0).unwrap();
        let decoded = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(decoded.dimensions(), (4, 2));
        // Exposure +1 doubles: 0.5 → 1.0 → 255, 0.25 → 0.5 → sRGB 0.7354 → 188.
        assert_eq!(decoded.get_pixel(0, 0).0, [255, 0, 255]);
        assert_eq!(decoded.get_pixel(1, 0).0, [188, 188, 188]);
        assert_eq!(decoded.get_pixel(2, 0).0, [255, 255, 255]);
        assert_eq!(decoded.get_pixel(3, 0).0, [0, 0, 0]);
        assert_eq!(
            decoded.get_pixel(1, 1).0,
            [0, 0, 0],
            "invalid texels are black"
        );
        assert_eq!(write_png_preview(&page, 1.0).unwrap(), png);
        let darker = image::load_from_memory(&write_png_preview(&page, 0.0).unwrap())
            .unwrap()
            .to_rgb8();
        assert_eq!(darker.get_pixel(0, 1).0, [188, 188, 188]);
    }

    #[test]
    fn tone_curve_is_identity_then_smooth_and_bounded() {
        assert_eq!(tone_map(0.5), 0.5);
        assert_eq!(tone_map(f32::NAN), 0.0);
        let k = SHOULDER;
        assert!((tone_map(k + 1e-4) - (k + 1e-4)).abs() < 1e-6);
        assert!(tone_map(100.0) <= 1.0 && tone_map(100.0) > 0.99);
        assert!(tone_map(2.0) > tone_map(1.5));
    }
}
