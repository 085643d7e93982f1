//! Dilation: grows solved texels outward into the gutters between charts, so bilinear
//! filtering and mipmapping in a renderer never blend in black.
//!
//! Each ring fills every invalid texel that has a valid 8-neighbour with the mean of those
//! neighbours, reading only texels valid before the ring (so the result does not depend on
//! scan order). Filled texels become valid for the next ring. Charts are separated by padding,
//! so a gutter texel takes its value from the nearest chart. Texels more than `radius` rings
//! away stay black and invalid.

use glam::Vec3;

use super::{LightmapPages, Page};

/// Grows the valid texels of every page by `radius` rings.
pub fn dilate(pages: &mut LightmapPages, radius: u32) {
    for page in &mut pages.pages {
        dilate_page(page, radius);
    }
}

fn dilate_page(page: &mut Page, radius: u32) {
    let (w, h) = (page.width as usize, page.height as usize);
    // The ring to fill next: invalid texels next to a valid one, each listed once.
    let mut ring: Vec<usize> = (0..w * h)
        .filter(|&k| !page.valid[k] && neighbours(k, w, h).any(|n| page.valid[n]))
        .collect();
    let mut queued = vec![false; w * h];
    for &k in &ring {
        queued[k] = true;
    }
    let mut filled: Vec<(usize, Vec3)> = Vec::with_capacity(ring.len());
    for _ in 0..radius {
        if ring.is_empty() {
            break;
        }
        // Compute the whole ring from the previous state, then apply it.
        filled.clear();
        for &k in &ring {
            let (sum, count) = neighbours(k, w, h)
                .filter(|&n| page.valid[n])
                .fold((Vec3::ZERO, 0u32), |(s, c), n| (s + page.rgb[n], c + 1));
            let mean = sum / count.max(1) as f32;
            filled.push((k, if mean.is_finite() { mean } else { Vec3::ZERO }));
        }
        for &(k, value) in &filled {
            page.rgb[k] = value;
            page.valid[k] = true;
        }
        // The next ring: invalid neighbours of what was just filled.
        ring.clear();
        for &(k, _) in &filled {
            for n in neighbours(k, w, h) {
                if !page.valid[n] && !queued[n] {
                    queued[n] = true;
                    ring.push(n);
                }
            }
        }
    }
}

/// The (up to 8) neighbours of texel `k` in a `w × h` page.
fn neighbours(k: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((k % w) as isize, (k / w) as isize);
    (-1..=1isize)
        .flat_map(move |dy| (-1..=1isize).map(move |dx| (x + dx, y + dy)))
        .filter(move |&(nx, ny)| {
            (nx, ny) != (x, y) && nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h
        })
        .map(move |(nx, ny)| ny as usize * w + nx as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn page(width: u32, height: u32, valid: &[((u32, u32), Vec3)]) -> LightmapPages {
        let n = (width * height) as usize;
        let mut page = Page {
            width,
            height,
            rgb: vec![Vec3::ZERO; n],
            valid: vec![false; n],
        };
        for &((x, y), v) in valid {
            let k = (y * width + x) as usize;
            page.rgb[k] = v;
            page.valid[k] = true;
        }
        LightmapPages { pages: vec![page] }
    }

    #[test]
    fn single_texel_grows_into_a_block_of_radius_rings() {
        let v = Vec3::new(0.25, 1.5, 3.0);
        let mut pages = page(9, 9, &[((4, 4), v)]);
        dilate(&mut pages, 2);
        let p = &pages.pages[0];
        for y in 0..9i32 {
            for x in 0..9i32 {
                let k = (y * 9 + x) as usize;
                let inside = (x - 4).abs() <= 2 && (y - 4).abs() <= 2;
                assert_eq!(p.valid[k], inside, "({x},{y})");
                assert_eq!(p.rgb[k], if inside { v } else { Vec3::ZERO }, "({x},{y})");
            }
        }
    }

    #[test]
    fn each_ring_reads_only_the_previous_ring() {
        // A scan-order (in-place) dilation would run the value along the whole row at once.
        let mut pages = page(6, 1, &[((0, 0), Vec3::ONE)]);
        dilate(&mut pages, 1);
        assert_eq!(
            pages.pages[0].valid,
            [true, true, false, false, false, false]
        );
        let mut pages = page(6, 1, &[((5, 0), Vec3::ONE)]);
        dilate(&mut pages, 1);
        assert_eq!(
            pages.pages[0].valid,
            [false, false, false, false, true, true]
        );
    }

    #[test]
    fn two_regions_fill_from_the_nearest_and_meet_halfway() {
        let (a, b) = (Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 4.0));
        let mut pages = page(7, 1, &[((0, 0), a), ((6, 0), b)]);
        dilate(&mut pages, 5);
        let p = &pages.pages[0];
        assert_eq!(&p.rgb[..3], [a, a, a]);
        assert_eq!(&p.rgb[4..], [b, b, b]);
        assert_eq!(p.rgb[3], (a + b) / 2.0);
        assert!(p.valid.iter().all(|&v| v));
    }

    #[test]
    fn radius_zero_and_empty_pages_change_nothing() {
        let mut pages = page(3, 3, &[((1, 1), Vec3::ONE)]);
        let before = pages.pages[0].clone();
        dilate(&mut pages, 0);
        assert_eq!(pages.pages[0].valid, before.valid);
        assert_eq!(pages.pages[0].rgb, before.rgb);

        let mut empty = page(4, 4, &[]);
        dilate(&mut empty, 3);
        assert!(empty.pages[0].valid.iter().all(|&v| !v));
        assert!(empty.pages[0].rgb.iter().all(|&v| v == Vec3::ZERO));
    }
}
