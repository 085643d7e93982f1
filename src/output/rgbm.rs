//! RGBM: lightmap pages as 8-bit RGBA PNG, for engines and platforms without HDR textures.
//!
//! A texel value `v` (linear `H/π`, RGB) is stored as a shared multiplier `M` in alpha and the
//! colour divided by it in RGB, all **linear** (no sRGB curve: load the PNG as a linear / non-sRGB
//! texture, or the decode is wrong):
//!
//! ```text
//!   encode:  m = max(v.r, v.g, v.b) / range            clamped to [0, 1]
//!            A = ⌈255·m⌉                                M rounded UP to the next 1/255 step
//!            RGB = round(255 · min(v / (A/255 · range), 1))
//!   decode:  rgb = (RGB / 255) · (A / 255) · range       (A = 0 decodes to black)
//! ```
//!
//! Rounding `M` up keeps `v/(M·range) ≤ 1`, so nothing below `range` clips; values above `range`
//! clamp to it (per channel, hue kept only up to the clamp). Error bound per channel: RGB is
//! rounded to the nearest 1/255 of `M·range`, so `|decode(encode(v)) − v| ≤ M·range/510`, and
//! `M·range < max(v) + range/255`, hence
//!
//! ```text
//!   |decoded − v| ≤ (max(v) + range/255) / 510
//! ```
//!
//! i.e. at most 1/255 of the brightest channel for every value above `range/255`, and an absolute
//! `range/130050` below it.
//!
//! | parameter | default | meaning                                                          |
//! |-----------|---------|------------------------------------------------------------------|
//! | `range`   | [`DEFAULT_RANGE`] = 8 | largest value stored; the dark-end step is `range/255²` |
//!
//! The bake writes `<stem>_lightmap<k>_rgbm.png` per page with `--rgbm` (range 8), through
//! `super::png::write_rgbm_png`. Invalid
//! (never solved nor dilated) and non-finite texels are stored as black.

use glam::Vec3;

use crate::lightmap::Page;

/// The range the bake encodes with: lightmaps of interiors lit to ordinary brightness stay
/// below 8; brighter texels clamp.
pub const DEFAULT_RANGE: f32 = 8.0;

/// One texel as RGBM bytes `[R, G, B, M]` (see the module docs).
#[inline]
pub(crate) fn encode_texel(v: Vec3, range: f32) -> [u8; 4] {
    let v = if v.is_finite() {
        v.max(Vec3::ZERO)
    } else {
        Vec3::ZERO
    };
    let m = (v.max_element() / range).clamp(0.0, 1.0);
    let a = (m * 255.0).ceil() as u8;
    if a == 0 {
        return [0; 4];
    }
    let scale = 255.0 / (a as f32 / 255.0 * range);
    let rgb = v.to_array().map(|c| (c * scale).round().min(255.0) as u8);
    [rgb[0], rgb[1], rgb[2], a]
}

/// The value RGBM bytes stand for: `rgb/255 · a/255 · range`.
#[inline]
pub(crate) fn decode_texel(rgbm: [u8; 4], range: f32) -> Vec3 {
    let [r, g, b, a] = rgbm.map(|c| c as f32 / 255.0);
    Vec3::new(r, g, b) * (a * range)
}

/// A page as RGBA8 bytes, row 0 at the top.
pub(crate) fn encode(page: &Page, range: f32) -> Vec<u8> {
    page.rgb
        .iter()
        .zip(&page.valid)
        .flat_map(|(v, &valid)| encode_texel(if valid { *v } else { Vec3::ZERO }, range))
        .collect()
}

/// RGBA8 bytes back to a page of `width × height` (every texel valid).
pub fn decode(rgba: &[u8], width: u32, height: u32, range: f32) -> Page {
    let rgb: Vec<Vec3> = rgba
        .chunks_exact(4)
        .map(|c| decode_texel([c[0], c[1], c[2], c[3]], range))
        .collect();
    Page {
        width,
        height,
        valid: vec![true; rgb.len()],
        rgb,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::png::write_rgbm_png;
    use crate::output::test_page;

    /// The bound of the module docs: `(max(v) + range/255) / 510` per channel.
    fn bound(v: Vec3, range: f32) -> f32 {
        (v.max_element() + range / 255.0) / 510.0
    }

    #[test]
    fn round_trip_error_stays_within_the_derived_bound() {
        let range = DEFAULT_RANGE;
        let mut worst_relative = 0.0f32;
        // Values over six decades, with channels in varied ratios.
        for k in 0..4000 {
            let t = k as f32 / 4000.0;
            let max = range * 10f32.powf(-6.0 * t);
            let v = Vec3::new(
                max,
                max * (0.1 + 0.9 * (k % 7) as f32 / 6.0),
                max * ((k % 13) as f32 / 12.0),
            );
            let d = decode_texel(encode_texel(v, range), range);
            let e = (d - v).abs().max_element();
            assert!(e <= bound(v, range) * 1.0001 + 1e-7, "{v} → {d}: error {e}");
            if v.max_element() >= range / 255.0 {
                worst_relative = worst_relative.max(e / v.max_element());
            }
        }
        assert!(worst_relative <= 1.0 / 255.0, "{worst_relative}");
        assert!(
            worst_relative > 1.0 / 2000.0,
            "8 bits cannot be this exact: {worst_relative}"
        );
    }

    #[test]
    fn values_above_range_clamp_and_black_stays_black() {
        let range = 4.0;
        assert_eq!(encode_texel(Vec3::splat(100.0), range), [255; 4]);
        assert_eq!(decode_texel([255; 4], range), Vec3::splat(range));
        let d = decode_texel(encode_texel(Vec3::new(10.0, 2.0, 0.0), range), range);
        // Per channel: red clamps to the range, green keeps its value (within the bound).
        assert_eq!((d.x, d.z), (range, 0.0));
        assert!((d.y - 2.0).abs() <= (range + range / 255.0) / 510.0, "{d}");
        for v in [
            Vec3::ZERO,
            Vec3::splat(-1.0),
            Vec3::splat(f32::NAN),
            Vec3::INFINITY,
        ] {
            assert_eq!(encode_texel(v, range), [0; 4], "{v}");
        }
        // Exactly the range: M = 1, RGB = 1.
        assert_eq!(
            encode_texel(Vec3::new(range, 0.0, 0.0), range),
            [255, 0, 0, 255]
        );
    }

    #[test]
    fn multiplier_rounds_up_so_the_brightest_channel_never_clips() {
        let range = DEFAULT_RANGE;
        for k in 1..2000 {
            let max = range * k as f32 / 2000.0;
            let [r, _, _, a] = encode_texel(Vec3::new(max, 0.0, 0.0), range);
            assert!(
                a as f32 / 255.0 * range >= max * (1.0 - 1e-6),
                "{max}: M {a}"
            );
            if a > 1 {
                assert!(
                    r >= 128,
                    "M is the smallest step that fits: {max} → R {r}, M {a}"
                );
            }
        }
    }

    #[test]
    fn png_decodes_to_the_page_within_the_bound() {
        let page = test_page();
        let png = write_rgbm_png(&page, DEFAULT_RANGE).unwrap();
        let image = image::load_from_memory(&png).unwrap().to_rgba8();
        assert_eq!(image.dimensions(), (3, 2));
        let back = decode(image.as_raw(), 3, 2, DEFAULT_RANGE);
        for (k, (d, v)) in back.rgb.iter().zip(&page.rgb).enumerate() {
            let v = if page.valid[k] {
                v.min(Vec3::splat(DEFAULT_RANGE))
            } else {
                Vec3::ZERO
            };
            assert!(
                (*d - v).abs().max_element() <= bound(v, DEFAULT_RANGE) * 1.0001,
                "{k}: {v} → {d}"
            );
        }
    }
}
