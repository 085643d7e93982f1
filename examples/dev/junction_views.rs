//! A rendered view against its path-traced reference, as a picture: for the guide's "Junction
//! splitting" (src/guide/baking.md) (`examples/gallery/junction_views.png`).
//!
//! ```text
//! cargo run --release --example junction_views -- OUT.png REF.exr IMAGE.exr [IMAGE.exr ...]
//! ```
//!
//! Top row: the reference and each image, tone-mapped as `lightbake render` writes PNGs. Bottom
//! row, under each image: its error per 4 × 4-pixel block (the blocks `lightbake compare --view`
//! compares), relative to the reference block plus 5% of the image's mean, from blue (20% or
//! more too dark) through white to red (20% or more too bright); under the reference, its own
//! standard error on the same scale (from `<REF stem>_stderr.exr`).

use std::path::{Path, PathBuf};

use lightbake::lightmap::Page;
use lightbake::output::{png, read_exr};

/// Side of the compared pixel blocks (as `lightbake compare --view`).
const BLOCK: u32 = 4;
/// Relative error at which the colour saturates.
const FULL_SCALE: f32 = 0.2;
/// Pixels between panels.
const GAP: u32 = 4;

fn main() {
    let args: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let [out, reference, images @ ..] = &args[..] else {
        panic!("usage: junction_views OUT.png REF.exr IMAGE.exr [IMAGE.exr ...]")
    };
    let read = |p: &Path| read_exr(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let r = read(reference);
    let stem = reference.file_stem().unwrap().to_string_lossy();
    let stderr = read(&reference.with_file_name(format!("{stem}_stderr.exr")));
    let images: Vec<Page> = images.iter().map(|p| read(p)).collect();
    let (w, h) = (r.width, r.height);
    assert!(images.iter().all(|i| (i.width, i.height) == (w, h)));
    let floor =
        0.05 * r.rgb.iter().map(|c| c.element_sum() / 3.0).sum::<f32>() / r.rgb.len() as f32;

    let panels = 1 + images.len() as u32;
    let (width, height) = (panels * w + (panels - 1) * GAP, 2 * h + GAP);
    let mut canvas = image::RgbImage::from_pixel(width, height, image::Rgb([255; 3]));
    let mut put = |panel: u32, row: u32, x: u32, y: u32, c: [u8; 3]| {
        canvas.put_pixel(panel * (w + GAP) + x, row * (h + GAP) + y, image::Rgb(c));
    };
    for (panel, image) in std::iter::once(&r).chain(&images).enumerate() {
        for y in 0..h {
            for x in 0..w {
                let c = image.rgb[(y * w + x) as usize];
                // As `lightbake render` writes a PNG at exposure 0.
                let c = c.to_array().map(|v| png::encode_srgb(png::tone_map(v)));
                put(panel as u32, 0, x, y, c);
            }
        }
    }
    // The error maps: signed for the images, the reference's standard error (≥ 0) under it.
    // `f` summed over a block's pixels (each pixel's channel mean).
    let block = |page: &Page, bx: u32, by: u32, f: fn(f32) -> f32| {
        let pixels = (by * BLOCK..(by + 1) * BLOCK)
            .flat_map(|y| (bx * BLOCK..(bx + 1) * BLOCK).map(move |x| (y * w + x) as usize));
        pixels
            .map(|i| f(page.rgb[i].element_sum() / 3.0))
            .sum::<f32>()
    };
    let pixels = (BLOCK * BLOCK) as f32;
    for by in 0..h / BLOCK {
        for bx in 0..w / BLOCK {
            let mean = |page: &Page| block(page, bx, by, |v| v) / pixels;
            let reference = mean(&r);
            let base = reference + floor;
            // The standard error of a block mean: √Σσ² / pixels.
            let noise = block(&stderr, bx, by, |s| s * s).sqrt() / pixels;
            let errors = std::iter::once(noise / base)
                .chain(images.iter().map(|i| (mean(i) - reference) / base));
            for (panel, e) in errors.enumerate() {
                for y in by * BLOCK..(by + 1) * BLOCK {
                    for x in bx * BLOCK..(bx + 1) * BLOCK {
                        put(panel as u32, 1, x, y, diverging(e));
                    }
                }
            }
        }
    }
    canvas
        .save(out)
        .unwrap_or_else(|e| panic!("{}: {e}", out.display()));
    println!("wrote {} ({width} × {height})", out.display());
}

/// Blue (−[`FULL_SCALE`] or less) through white (0) to red (+[`FULL_SCALE`] or more).
fn diverging(e: f32) -> [u8; 3] {
    let t = (e / FULL_SCALE).clamp(-1.0, 1.0);
    let fade = (255.0 * (1.0 - t.abs())).round() as u8;
    match t >= 0.0 {
        true => [255, fade, fade],
        false => [fade, fade, 255],
    }
}
