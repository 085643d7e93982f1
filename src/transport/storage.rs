//! How stored rows are held in memory: f32 form factors, or — for Monte Carlo rows — the exact
//! ray counts they come from.
//!
//! A Monte Carlo entry is `F_ij = hits_ij / K_i` (hits of texel `j` among the `K_i` rays of
//! texel `i`), so a row is stored losslessly as `K_i` and, per entry, the step from the previous
//! column and the hit count. A non-empty row of `m` entries is
//!
//! ```text
//!   varint(m << 1 | wide) · varint(first column) · varint(count bytes)
//!   · steps (m bytes, or 2m when wide) · counts · far steps (u16 each, or u32 when wide)
//! ```
//!
//! Each step is `gap << 1 | (hits > 1)` (`gap` = column − previous column − 1, the first
//! column counting as gap 0; columns are sorted and distinct) in one byte for gaps up to 126,
//! or two bytes for gaps up to 32766 in a `wide` row. A larger gap is written as the step
//! `ESCAPE | (hits > 1)` (`0xFE`, or `0xFFFE` wide) with the gap itself in the far stream
//! (u16, or u32 wide). Each entry hit more than once takes the next count byte, `hits − 2`
//! (255 escapes to a 4-byte count). The builder picks per row the width that takes fewer
//! bytes (most steps are short in small scenes, most need two bytes in large ones).
//! Decoding rebuilds the very f32 the builder used to store (`hits as f32 / K_i as f32`), so
//! every sum is bit-identical.
//!
//! Why fixed-width steps with side streams: the solvers' inner loop must keep up with a loop
//! over f32 weights. A varint's length decides where the next step starts, a chain through a
//! memory load per entry (sweeps were 2–3× slower than over f32 weights); here the step of
//! entry `n` is at `n` (or `2n`), and the count and far streams advance by a flag, so the loop
//! has no branch and no load-to-address chain (the side streams are read whether or not the
//! entry uses them: the storage ends in padding).

use std::iter::{Copied, Zip};
use std::slice::Iter;

/// Stored rows: one API over both representations.
#[derive(Clone, Debug, PartialEq)]
pub enum Rows {
    /// f32 form factors (point, polygon and all-pairs rows; empty rows).
    Weights(WeightRows),
    /// Monte Carlo rows as ray counts (exact, see the module docs).
    Counts(CountRows),
}

impl Default for Rows {
    fn default() -> Rows {
        Rows::Weights(WeightRows::default())
    }
}

/// Compressed sparse rows with an f32 weight per entry.
#[derive(Clone, Debug, PartialEq)]
pub struct WeightRows {
    /// Row `i` is `col[row_start[i]..row_start[i+1]]`, `f[…]` (length = rows + 1).
    pub row_start: Vec<u32>,
    /// Source texel of each entry.
    pub col: Vec<u32>,
    /// `F_ij` of each entry.
    pub f: Vec<f32>,
}

impl Default for WeightRows {
    fn default() -> WeightRows {
        WeightRows {
            row_start: vec![0],
            col: Vec::new(),
            f: Vec::new(),
        }
    }
}

/// Monte Carlo rows as ray counts (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct CountRows {
    /// Row `i` is `bytes[row_start[i]..row_start[i+1]]` (u64: rows of large bakes pass 4 GiB).
    row_start: Vec<u64>,
    /// Gathering rays `K_i` of each row: the denominator of its weights.
    rays: Vec<u32>,
    /// The rows, then [`PADDING`] bytes: the side streams are read before a step says whether
    /// it uses them.
    bytes: Vec<u8>,
    entries: u64,
}

/// The most rays a row may have for its weights to be exact ([`weight`]); the configuration
/// allows at most this many.
pub const MAX_RAYS: u32 = 1 << 20;
/// Bytes after the last row: the widest read past a row's end (a far step).
const PADDING: usize = 4;
/// The count byte that says a 4-byte count (little-endian `hits`) follows.
const COUNT_ESCAPE: u8 = 255;

/// One step width: one byte with u16 far steps, or two bytes with u32 far steps.
trait Width {
    const STEP_BYTES: usize;
    const FAR_BYTES: usize;
    /// The least step that says "the gap is in the far stream" (its low bit is the flag).
    const ESCAPE: u32;
    /// The largest gap a far step holds.
    const FAR_MAX: u32;
}
struct Narrow;
struct Wide;
impl Width for Narrow {
    const STEP_BYTES: usize = 1;
    const FAR_BYTES: usize = 2;
    const ESCAPE: u32 = 0xFE;
    const FAR_MAX: u32 = u16::MAX as u32;
}
impl Width for Wide {
    const STEP_BYTES: usize = 2;
    const FAR_BYTES: usize = 4;
    const ESCAPE: u32 = 0xFFFE;
    const FAR_MAX: u32 = u32::MAX;
}

/// The little-endian unsigned integer of `W` bytes at `bytes[at..]`.
#[inline(always)]
fn read_le<const W: usize>(bytes: &[u8], at: usize) -> u32 {
    let mut word = [0u8; 4];
    word[..W].copy_from_slice(&bytes[at..at + W]);
    u32::from_le_bytes(word)
}

impl Default for CountRows {
    fn default() -> CountRows {
        CountRows {
            row_start: vec![0],
            rays: Vec::new(),
            bytes: vec![0; PADDING],
            entries: 0,
        }
    }
}

impl CountRows {
    /// Appends a row from the source texels its `rays` rays hit, sorted (a texel hit `n` times
    /// appears `n` times).
    pub fn push_row(&mut self, sorted_hits: &[u32], rays: u32) {
        debug_assert!(rays <= MAX_RAYS, "{rays} rays: weights would not be exact");
        self.bytes.truncate(self.bytes.len() - PADDING);
        if let Some(&first) = sorted_hits.first() {
            let runs = || sorted_hits.chunk_by(|a, b| a == b);
            // Each entry as (gap, hits); the first column counts as gap 0.
            let entries = || {
                let mut previous = first.wrapping_sub(1);
                runs().map(move |run| {
                    let gap = run[0].wrapping_sub(previous).wrapping_sub(1);
                    previous = run[0];
                    (gap, run.len())
                })
            };
            let m = runs().count();
            let far_bytes = |near_max: u32, far: usize| {
                far * entries().filter(|&(gap, _)| gap > near_max).count()
            };
            let narrow = (entries().all(|(gap, _)| gap <= Narrow::FAR_MAX))
                .then(|| m + far_bytes(Narrow::ESCAPE / 2 - 1, Narrow::FAR_BYTES));
            let wide =
                narrow.is_none_or(|n| 2 * m + far_bytes(Wide::ESCAPE / 2 - 1, Wide::FAR_BYTES) < n);
            let count_bytes = |hits: usize| match hits {
                1 => 0,
                2..=256 => 1,
                _ => 5,
            };
            write_varint(&mut self.bytes, (m as u64) << 1 | wide as u64);
            write_varint(&mut self.bytes, first as u64);
            write_varint(&mut self.bytes, runs().map(|r| count_bytes(r.len())).sum());
            match wide {
                true => self.push_steps::<Wide>(entries()),
                false => self.push_steps::<Narrow>(entries()),
            }
            self.entries += m as u64;
        }
        self.row_start.push(self.bytes.len() as u64);
        self.bytes.extend([0; PADDING]);
        self.rays.push(rays);
    }

    /// The steps, counts and far steps of a row's `(gap, hits)` entries, with width `W`.
    fn push_steps<W: Width>(&mut self, entries: impl Iterator<Item = (u32, usize)> + Clone) {
        let near = |gap: u32| gap < W::ESCAPE / 2;
        for (gap, hits) in entries.clone() {
            let step = if near(gap) { gap << 1 } else { W::ESCAPE } | (hits > 1) as u32;
            self.bytes
                .extend_from_slice(&step.to_le_bytes()[..W::STEP_BYTES]);
        }
        for (_, hits) in entries.clone().filter(|&(_, hits)| hits > 1) {
            match u8::try_from(hits - 2) {
                Ok(b) if b < COUNT_ESCAPE => self.bytes.push(b),
                _ => {
                    self.bytes.push(COUNT_ESCAPE);
                    self.bytes.extend((hits as u32).to_le_bytes());
                }
            }
        }
        for (gap, _) in entries.filter(|&(gap, _)| !near(gap)) {
            self.bytes
                .extend_from_slice(&gap.to_le_bytes()[..W::FAR_BYTES]);
        }
    }

    /// Empties the last row (its ray count stays).
    pub fn clear_last_row(&mut self) {
        let n = self.rays.len();
        if n == 0 {
            return;
        }
        let start = self.row_start[n - 1];
        self.entries -= self.row(n - 1).len() as u64;
        self.bytes.truncate(start as usize);
        self.bytes.extend([0; PADDING]);
        self.row_start[n] = start;
    }

    /// Appends the rows of `other` after these.
    pub fn append(&mut self, other: CountRows) {
        let base = *self.row_start.last().unwrap();
        self.row_start
            .extend(other.row_start[1..].iter().map(|s| s + base));
        self.rays.extend(other.rays);
        self.bytes.truncate(self.bytes.len() - PADDING);
        self.bytes.extend(other.bytes);
        self.entries += other.entries;
    }

    /// Rows held.
    pub fn len(&self) -> usize {
        self.rays.len()
    }
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// The entries of row `i` as (source texel, `hits / K_i`).
    #[inline]
    pub fn row(&self, i: usize) -> CountRow<'_> {
        let (start, end) = (self.row_start[i] as usize, self.row_start[i + 1] as usize);
        let mut row = CountRow {
            bytes: &[],
            left: 0,
            wide: false,
            step: 0,
            counts: 0,
            far: 0,
            col: 0,
            inv_rays: 1.0 / self.rays[i] as f64,
        };
        if end > start {
            // From the row's start to the storage's end (its padding included).
            let bytes = &self.bytes[start..];
            let (header, at) = read_varint(bytes, 0);
            let (first, at) = read_varint(bytes, at);
            let (count_bytes, at) = read_varint(bytes, at);
            let m = (header >> 1) as usize;
            row.wide = header & 1 == 1;
            row.bytes = bytes;
            row.left = m;
            row.step = at;
            row.counts = at + m * if row.wide { Wide::STEP_BYTES } else { 1 };
            row.far = row.counts + count_bytes as usize;
            row.col = (first as u32).wrapping_sub(1);
        }
        row
    }
}

fn write_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The varint at `bytes[at..]` and the position after it.
fn read_varint(bytes: &[u8], mut at: usize) -> (u64, usize) {
    let (mut v, mut shift) = (0u64, 0);
    loop {
        let b = bytes[at];
        at += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b < 0x80 {
            return (v, at);
        }
        shift += 7;
    }
}

/// The entries of one count row, decoded as they are read.
#[derive(Clone, Debug)]
pub struct CountRow<'a> {
    /// From the row's start to the end of the storage (its padding included).
    bytes: &'a [u8],
    /// Entries not yet read.
    left: usize,
    /// Two-byte steps with u32 far steps (else one byte, u16).
    wide: bool,
    /// Positions of the next step, count byte and far step.
    step: usize,
    counts: usize,
    far: usize,
    /// The previous entry's column (the first column − 1 before the first).
    col: u32,
    /// `1 / K_i` in f64: `hits · (1 / K_i)` rounded to f32 is exactly `hits as f32 / K_i as f32`
    /// (see [`weight`]), without a division per entry.
    inv_rays: f64,
}

impl CountRow<'_> {
    /// The next entry, in a row of width `W` with entries left.
    #[inline(always)]
    fn decode<W: Width>(&mut self) -> (u32, f32) {
        let step = match W::STEP_BYTES {
            1 => read_le::<1>(self.bytes, self.step),
            _ => read_le::<2>(self.bytes, self.step),
        };
        let far = match W::FAR_BYTES {
            2 => read_le::<2>(self.bytes, self.far),
            _ => read_le::<4>(self.bytes, self.far),
        };
        self.step += W::STEP_BYTES;
        let escaped = step >= W::ESCAPE;
        self.far += escaped as usize * W::FAR_BYTES;
        let gap = if escaped { far } else { step >> 1 };
        self.col = self.col.wrapping_add(gap).wrapping_add(1);
        // The count byte is read whether or not the entry is repeated (in bounds: the far
        // steps or the padding follow), and a single hit divided like a repeated one, so that
        // no branch depends on the flag (a repeated hit is a coin toss in small scenes).
        let repeated = step & 1;
        let count = self.bytes[self.counts] as u32 * repeated;
        let escaped_count = count == COUNT_ESCAPE as u32;
        let hits = match escaped_count {
            true => escaped_count_at(self.bytes, self.counts),
            false => 1 + repeated + count,
        };
        self.counts += repeated as usize + 4 * escaped_count as usize;
        (self.col, scaled(hits, self.inv_rays))
    }

    /// The rest of the row folded with `f`: the solvers' path, one loop per width.
    #[inline(always)]
    fn fold_width<W: Width, B, F: FnMut(B, (u32, f32)) -> B>(mut self, init: B, mut f: F) -> B {
        let mut acc = init;
        for _ in 0..self.left {
            acc = f(acc, self.decode::<W>());
        }
        acc
    }
}

/// The weight of `hits` of `rays` rays as the solvers' rows hold it, `hits as f32 / rays as f32`
/// (the f32 the builder stored before counts), computed as [`CountRow`] does: `hits · (1 / K)`
/// in f64, rounded to f32. That is the same f32: the f64 product is within 2⁻⁵² (relative) of
/// `hits / K`, while a quotient of integers below 2²⁴ (`hits ≤ K ≤ 2²⁰`, the configuration's
/// limit) that is not an f32 is at least `1 / (K · 2²⁵) ≥ 2⁻⁴⁵` from every f32 rounding boundary
/// (a boundary has 25 significant bits, the quotient's distance to it is a multiple of
/// `1 / (K · 2²⁴⁻ᵉ)`), and one that is an f32 rounds back to itself.
#[cfg(test)]
fn weight(hits: u32, rays: u32) -> f32 {
    scaled(hits, 1.0 / rays as f64)
}

/// `hits · inv_rays` as f32 ([`weight`]).
#[inline(always)]
fn scaled(hits: u32, inv_rays: f64) -> f32 {
    (hits as f64 * inv_rays) as f32
}

/// The 4-byte count after the escape byte at `at`.
#[cold]
#[inline(never)]
fn escaped_count_at(bytes: &[u8], at: usize) -> u32 {
    read_le::<4>(bytes, at + 1)
}

impl Iterator for CountRow<'_> {
    type Item = (u32, f32);

    #[inline]
    fn next(&mut self) -> Option<(u32, f32)> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        Some(match self.wide {
            true => self.decode::<Wide>(),
            false => self.decode::<Narrow>(),
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.left, Some(self.left))
    }

    #[inline]
    fn fold<B, F: FnMut(B, (u32, f32)) -> B>(self, init: B, f: F) -> B {
        match self.wide {
            true => self.fold_width::<Wide, B, F>(init, f),
            false => self.fold_width::<Narrow, B, F>(init, f),
        }
    }
}

impl ExactSizeIterator for CountRow<'_> {}

impl Rows {
    /// Rows held.
    pub fn len(&self) -> usize {
        match self {
            Rows::Weights(w) => w.row_start.len() - 1,
            Rows::Counts(c) => c.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Entries over all rows.
    pub fn entries(&self) -> u64 {
        match self {
            Rows::Weights(w) => w.col.len() as u64,
            Rows::Counts(c) => c.entries,
        }
    }

    /// Bytes the rows take in memory (lengths, not capacities).
    pub fn bytes(&self) -> u64 {
        let size = |n: usize, each: usize| (n * each) as u64;
        match self {
            Rows::Weights(w) => size(w.row_start.len(), 4) + size(w.col.len(), 8),
            Rows::Counts(c) => {
                size(c.row_start.len(), 8) + size(c.rays.len(), 4) + c.bytes.len() as u64
            }
        }
    }

    /// The entries of row `i` as (source texel, F_ij).
    #[inline]
    pub fn row(&self, i: usize) -> Row<'_> {
        match self {
            Rows::Weights(w) => {
                let r = w.row_start[i] as usize..w.row_start[i + 1] as usize;
                Row::Weights(w.col[r.clone()].iter().copied().zip(w.f[r].iter().copied()))
            }
            Rows::Counts(c) => Row::Counts(c.row(i)),
        }
    }

    /// The same rows with f32 weights (as Monte Carlo rows were stored before counts).
    pub fn to_weights(&self) -> WeightRows {
        let mut w = WeightRows::default();
        for i in 0..self.len() {
            for (j, f) in self.row(i) {
                w.col.push(j);
                w.f.push(f);
            }
            w.row_start.push(w.col.len() as u32);
        }
        w
    }
}

/// One row's entries, whichever the storage.
#[derive(Clone, Debug)]
pub enum Row<'a> {
    Weights(Zip<Copied<Iter<'a, u32>>, Copied<Iter<'a, f32>>>),
    Counts(CountRow<'a>),
}

impl Iterator for Row<'_> {
    type Item = (u32, f32);

    #[inline]
    fn next(&mut self) -> Option<(u32, f32)> {
        match self {
            Row::Weights(it) => it.next(),
            Row::Counts(it) => it.next(),
        }
    }

    /// Once per row, not per entry: the solvers' sums run in the representation's own loop.
    #[inline]
    fn fold<B, F: FnMut(B, (u32, f32)) -> B>(self, init: B, f: F) -> B {
        match self {
            Row::Weights(it) => it.fold(init, f),
            Row::Counts(it) => it.fold(init, f),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    /// The sorted hits of a random row: `k` rays over columns below `n`, clustered (most
    /// steps small, some far jumps, repeated hits), some rays lost.
    fn random_hits(rng: &mut Rng, n: u32, k: u32) -> Vec<u32> {
        let mut hits = Vec::new();
        let mut col = rng.next_u32() % n;
        for _ in 0..k {
            let u = rng.next_f32();
            if u < 0.1 {
                continue; // escaped
            }
            let v = rng.next_f32();
            col = if u < 0.2 {
                rng.next_u32() % n // a far jump
            } else if u < 0.5 {
                col // a repeated hit
            } else {
                col.saturating_add((v * 200.0) as u32).min(n - 1)
            };
            hits.push(col);
        }
        hits.sort_unstable();
        hits
    }

    /// Every row decodes to its columns and exactly `hits as f32 / K as f32`, the f32 the
    /// Monte Carlo builder stored before counts, for random rows with large column jumps,
    /// large counts, the largest columns and empty rows.
    #[test]
    fn counts_round_trip_to_the_old_weights() {
        let mut rng = Rng::new(7, 0, 0);
        let mut rows = CountRows::default();
        let mut expected: Vec<Vec<(u32, f32)>> = Vec::new();
        let mut add = |rows: &mut CountRows, hits: Vec<u32>, k: u32| {
            rows.push_row(&hits, k);
            let kf = k as f32;
            expected.push(
                hits.chunk_by(|a, b| a == b)
                    .map(|run| (run[0], run.len() as f32 / kf))
                    .collect(),
            );
        };
        for r in 0..2000 {
            let n = [10, 1000, 1 << 20, u32::MAX][r % 4];
            let k = 1 + (rng.next_f32() * 4096.0) as u32;
            add(&mut rows, random_hits(&mut rng, n, k), k);
        }
        add(&mut rows, vec![], 16);
        add(&mut rows, vec![0, u32::MAX - 1, u32::MAX, u32::MAX], 7);
        add(&mut rows, vec![5; 100_000], 100_000);
        let rows = Rows::Counts(rows);
        assert_eq!(rows.len(), 2003);
        let entries: usize = expected.iter().map(Vec::len).sum();
        assert_eq!(rows.entries(), entries as u64);
        for (i, want) in expected.iter().enumerate() {
            let got: Vec<(u32, f32)> = rows.row(i).collect();
            let bits =
                |r: &[(u32, f32)]| r.iter().map(|&(j, f)| (j, f.to_bits())).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(want), "row {i}");
            // fold (the solvers' path) sees the same entries in the same order
            let folded = rows.row(i).fold(Vec::new(), |mut v, e| {
                v.push(e);
                v
            });
            assert_eq!(bits(&folded), bits(want), "row {i}");
        }
        let w = Rows::Weights(rows.to_weights());
        assert!((0..rows.len()).all(|i| rows.row(i).eq(w.row(i))));
    }

    /// A bake's Monte Carlo rows stored as counts and the same rows as f32 weights (the storage
    /// before counts) give bit-identical solutions with every row solver.
    #[test]
    fn solutions_are_identical_with_counts_and_weights() {
        use crate::config::{BakeConfig, RowSolver};
        use crate::transport::Transport;
        use crate::{NoProgress, compute, solve};
        let mut c = BakeConfig::draft();
        c.auto = None;
        c.transport.gather_rays = 128;
        let fixture = crate::solve::tests::fixture("cornell_box.gltf");
        let baked = compute(&fixture, &c, &NoProgress).unwrap();
        let counts = &baked.transport;
        assert!(matches!(counts.rows, Rows::Counts(_)) && counts.rows.entries() > 0);
        let weights = Transport {
            rows: Rows::Weights(counts.rows.to_weights()),
            ..counts.clone()
        };
        assert!(counts.rows.bytes() * 4 < weights.rows.bytes());
        for solver in [
            RowSolver::Jacobi,
            RowSolver::GaussSeidel,
            RowSolver::Southwell,
        ] {
            let solve = |t| solve::solve(t, &baked.texels, solver, &c.solve, &NoProgress).unwrap();
            let (a, b) = (solve(counts), solve(&weights));
            assert!(a.irradiance == b.irradiance, "{solver:?}");
            assert_eq!(a.history.len(), b.history.len());
            if solver == RowSolver::Jacobi {
                assert!(a.irradiance == baked.solution.irradiance);
            }
        }
    }

    /// `weight` (a multiplication in f64) is the f32 quotient for every row the configuration
    /// allows: all counts of every K up to 4096, random ones up to the limit.
    #[test]
    fn weights_are_the_f32_quotients() {
        for rays in 1..=4096 {
            for hits in 1..=rays {
                assert_eq!(
                    weight(hits, rays),
                    hits as f32 / rays as f32,
                    "{hits}/{rays}"
                );
            }
        }
        let mut rng = Rng::new(3, 0, 0);
        for _ in 0..4_000_000 {
            let rays = 1 + rng.next_u32() % MAX_RAYS;
            let hits = 1 + rng.next_u32() % rays;
            assert_eq!(
                weight(hits, rays),
                hits as f32 / rays as f32,
                "{hits}/{rays}"
            );
        }
        let mut c = crate::config::BakeConfig::draft();
        c.transport.gather_rays = MAX_RAYS;
        assert!(c.validate().is_ok());
        c.transport.gather_rays = MAX_RAYS + 1;
        assert!(c.validate().is_err());
    }

    /// Concatenating chunks and clearing a row keep the other rows intact.
    #[test]
    fn append_and_clear_keep_rows() {
        let mut a = CountRows::default();
        a.push_row(&[1, 1, 300], 4);
        a.push_row(&[2], 2);
        a.clear_last_row();
        let mut b = CountRows::default();
        b.push_row(&[0, 70_000], 3);
        a.append(b);
        let rows = Rows::Counts(a);
        let row = |i| rows.row(i).collect::<Vec<_>>();
        assert_eq!(row(0), [(1, 0.5), (300, 0.25)]);
        assert_eq!(row(1), []);
        assert_eq!(row(2), [(0, 1.0 / 3.0), (70_000, 1.0 / 3.0)]);
        assert_eq!(rows.entries(), 4);
    }
}
