//! Packing without xatlas: rectangles on shelves, and the density pilot's outlines.
//!
//! The density pilot's atlas (`crate::atlas::build_quick`) holds only convex planar outlines,
//! each a chart whose map is known. xatlas would chart each again before packing, and its 2019
//! charting allocates some 300 KB per chart whatever its size (edge hash maps of at least 4096
//! slots for the chart group's mesh and the chart's): 1460 outlines of the furnished interior
//! took 380 MB at the pilot's peak for a 48k-texel atlas. Here each outline is turned to its
//! smallest bounding rectangle and the rectangles are shelf-packed; packing is looser than
//! xatlas' (rectangles, not rasterised shapes), which costs page area, not texels.

use glam::{DMat2, DVec2};

/// Places rects (`[w, h]` texels, tallest first) on shelves of pages at most `limit`
/// (`[width, height]`) texels: each into the first shelf (any page) with room, else a new
/// shelf, else a new page. Returns (page, [x, y]) per rect.
pub(super) fn shelf_pack(sizes: &[[u32; 2]], limit: [u32; 2]) -> Vec<(u32, [u32; 2])> {
    struct Shelf {
        page: u32,
        y: u32,
        height: u32,
        used: u32,
    }
    let [width, height] = limit;
    let mut shelves: Vec<Shelf> = Vec::new();
    let mut page_height: Vec<u32> = Vec::new();
    sizes
        .iter()
        .map(|&[w, h]| {
            debug_assert!(
                w <= width && h <= height,
                "a {w}×{h} rect on a {limit:?} page"
            );
            if let Some(shelf) = (shelves.iter_mut()).find(|s| s.height >= h && s.used + w <= width)
            {
                let at = (shelf.page, [shelf.used, shelf.y]);
                shelf.used += w;
                return at;
            }
            let page = match page_height.iter().position(|&used| used + h <= height) {
                Some(page) => page,
                None => {
                    page_height.push(0);
                    page_height.len() - 1
                }
            };
            let y = page_height[page];
            page_height[page] += h;
            shelves.push(Shelf {
                page: page as u32,
                y,
                height: h,
                used: w,
            });
            (page as u32, [0, y])
        })
        .collect()
}

/// xatlas' margin below whole texels when it stretches a chart's extent (`kEpsilon`).
const STRETCH_MARGIN: f64 = 1e-4;

/// Where each convex outline (counter-clockwise, in texels) lies: (page, linear part, offset)
/// with `page_texel = linear · p + offset`, on pages of at most `side`² texels kept roughly
/// square. As xatlas lays out a planar chart, so that the pilot's texels are the final
/// atlas's kind: turned to its smallest bounding rectangle, stretched to whole texels (just
/// under), half a texel in from its cell's corner (it touches one more texel each way), at
/// least `padding` texels apart (the gap right of and below each chart). `None` when an
/// outline does not fit a page.
pub(super) fn pack_outlines(
    outlines: &[&[DVec2]],
    side: u32,
    padding: u32,
) -> Option<Vec<(i32, DMat2, DVec2)>> {
    let frames: Vec<(DMat2, DVec2, [u32; 2])> = outlines
        .iter()
        .map(|outline| {
            let (turn, low, size) = smallest_rectangle(outline);
            let whole = size.ceil().max(DVec2::ONE);
            let stretch = DVec2::select(
                size.cmpgt(DVec2::ZERO),
                (whole - STRETCH_MARGIN) / size,
                DVec2::ONE,
            );
            // The low corner, turned and stretched.
            let cell = whole.as_uvec2() + 1 + padding;
            let linear = DMat2::from_diagonal(stretch) * turn;
            (linear, stretch * low, [cell.x, cell.y])
        })
        .collect();
    if frames.iter().any(|f| f.2[0] > side || f.2[1] > side) {
        return None;
    }
    let mut order: Vec<usize> = (0..outlines.len()).collect();
    order.sort_by_key(|&i| {
        let [w, h] = frames[i].2;
        (std::cmp::Reverse(h), std::cmp::Reverse(w), i)
    });
    let area: f64 = frames
        .iter()
        .map(|f| f64::from(f.2[0]) * f64::from(f.2[1]))
        .sum();
    let widest = frames.iter().map(|f| f.2[0]).max().unwrap_or(1);
    // Shelves as wide as a square page holding everything, so pages are not long strips.
    let width = ((1.1 * area).sqrt().ceil() as u32).clamp(widest, side);
    let sizes: Vec<[u32; 2]> = order.iter().map(|&i| frames[i].2).collect();
    let placed = shelf_pack(&sizes, [width, side]);
    let mut out = vec![(0, DMat2::IDENTITY, DVec2::ZERO); outlines.len()];
    for (&i, &(page, [x, y])) in order.iter().zip(&placed) {
        let (linear, low, _) = frames[i];
        let corner = DVec2::new(f64::from(x), f64::from(y)) + 0.5;
        out[i] = (page as i32, linear, corner - low);
    }
    Some(out)
}

/// The rotation that turns a convex `outline` into its smallest axis-aligned bounding
/// rectangle (one side along an outline edge; lying, not standing), and that rectangle's low
/// corner and size in the turned coordinates.
fn smallest_rectangle(outline: &[DVec2]) -> (DMat2, DVec2, DVec2) {
    let bounds = |turn: DMat2| {
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for &p in outline {
            let q = turn * p;
            (lo, hi) = (lo.min(q), hi.max(q));
        }
        (lo, hi - lo)
    };
    let mut best = (DMat2::IDENTITY, bounds(DMat2::IDENTITY));
    for (i, &a) in outline.iter().enumerate() {
        let u = (outline[(i + 1) % outline.len()] - a).normalize_or_zero();
        if u == DVec2::ZERO {
            continue;
        }
        // Rows u and its perpendicular: p ↦ (u·p, u⊥·p), a rotation.
        let turn = DMat2::from_cols(DVec2::new(u.x, -u.y), DVec2::new(u.y, u.x));
        let b = bounds(turn);
        if b.1.x * b.1.y < best.1.1.x * best.1.1.y {
            best = (turn, b);
        }
    }
    let (mut turn, (mut low, mut size)) = best;
    if size.y > size.x {
        // A quarter turn: p ↦ (u⊥·p, −u·p).
        turn = DMat2::from_cols(DVec2::new(0.0, -1.0), DVec2::new(1.0, 0.0)) * turn;
        (low, size) = bounds(turn);
    }
    (turn, low, size)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn apart(sizes: &[[u32; 2]], placed: &[(u32, [u32; 2])], limit: [u32; 2]) {
        for (a, (pa, [xa, ya])) in placed.iter().enumerate() {
            let [wa, ha] = sizes[a];
            assert!(xa + wa <= limit[0] && ya + ha <= limit[1]);
            for (b, (pb, [xb, yb])) in placed.iter().enumerate().skip(a + 1) {
                let [wb, hb] = sizes[b];
                let apart = pa != pb
                    || xa + wa <= *xb
                    || xb + wb <= *xa
                    || ya + ha <= *yb
                    || yb + hb <= *ya;
                assert!(apart, "rects {a} and {b} overlap");
            }
        }
    }

    #[test]
    fn shelf_packing_never_overlaps_and_opens_pages() {
        let sizes: Vec<[u32; 2]> = (0..40u32).map(|k| [10 + 7 * (k % 5), 30 - k / 2]).collect();
        let placed = shelf_pack(&sizes, [64, 64]);
        assert!(placed.iter().map(|p| p.0).max().unwrap() >= 1);
        apart(&sizes, &placed, [64, 64]);
        let placed = shelf_pack(&sizes, [48, 64]);
        apart(&sizes, &placed, [48, 64]);
    }

    #[test]
    fn a_turned_rectangle_is_laid_flat_along_its_edges() {
        // A 2 × 6 rectangle turned by 30°: its smallest box is 6 × 2, lying.
        let (s, c) = (0.5f64, 0.75f64.sqrt());
        let r = DMat2::from_cols(DVec2::new(c, s), DVec2::new(-s, c));
        let outline: Vec<DVec2> = [[0.0, 0.0], [2.0, 0.0], [2.0, 6.0], [0.0, 6.0]]
            .map(|p| r * DVec2::from(p) + 3.0)
            .to_vec();
        let (turn, low, size) = smallest_rectangle(&outline);
        assert!(
            (size - DVec2::new(6.0, 2.0)).abs().max_element() < 1e-9,
            "{size}"
        );
        assert!(
            (turn.determinant() - 1.0).abs() < 1e-12,
            "a rotation, not a mirror"
        );
        for p in &outline {
            let q = turn * *p - low;
            assert!(q.min_element() > -1e-9 && q.x < 6.0 + 1e-9 && q.y < 2.0 + 1e-9);
        }
    }

    #[test]
    fn packed_outlines_keep_their_gap_and_shape() {
        let square = |k: f64| {
            vec![
                DVec2::ZERO,
                DVec2::new(k, 0.0),
                DVec2::new(k, k),
                DVec2::new(0.0, k),
            ]
        };
        let shapes: Vec<Vec<DVec2>> = (1..30).map(|k| square(0.5 + k as f64 * 0.7)).collect();
        let outlines: Vec<&[DVec2]> = shapes.iter().map(|s| s.as_slice()).collect();
        let placed = pack_outlines(&outlines, 64, 2).unwrap();
        // Each chart's box in its page, grown by the padding, overlaps no other's.
        let boxes: Vec<(i32, DVec2, DVec2)> = placed
            .iter()
            .zip(&shapes)
            .map(|(&(page, turn, offset), shape)| {
                let q: Vec<DVec2> = shape.iter().map(|&p| turn * p + offset).collect();
                let lo = q.iter().fold(DVec2::INFINITY, |a, &b| a.min(b));
                let hi = q.iter().fold(DVec2::NEG_INFINITY, |a, &b| a.max(b));
                assert!(lo.min_element() >= 0.5 - 1e-9 && hi.max_element() <= 64.0 + 1e-9);
                // Stretched to whole texels, just under.
                let whole = (shape[2] - shape[0]).ceil();
                let size = hi - lo;
                assert!(
                    (size - whole).abs().max_element() < 2e-4,
                    "{size} for {whole}"
                );
                assert!(size.cmplt(whole).all());
                (page, lo, hi)
            })
            .collect();
        for (a, (pa, la, ha)) in boxes.iter().enumerate() {
            for (pb, lb, hb) in boxes.iter().skip(a + 1) {
                // Texels touched: floor(lo) up to ceil(hi) − 1; then the padding.
                let gap = (lb.floor() - ha.ceil())
                    .max(la.floor() - hb.ceil())
                    .max_element();
                assert!(pa != pb || gap >= 2.0, "charts closer than the padding");
            }
        }
        assert!(pack_outlines(&[&square(80.0)], 64, 2).is_none());
    }
}
