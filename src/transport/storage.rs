//! How stored rows are held in memory: f32 form factors, or — for Monte Carlo rows — the exact
//! ray counts they come from.
//!
//! A Monte Carlo entry is `F_ij = hits_ij / K_i` (hits of texel `j` among the `K_i` rays of
//! texel `i`), so a row is stored losslessly as `K_i` and, per entry, the step from the previous
//! column and the hit count. A non-empty row's bytes are
//!
//! ```text
//!   varint(m) · counts (m bytes) · steps (one varint per entry)
//! ```
//!
//! where each step is the LEB128 varint `gap << 1 | (hits > 1)` (`gap` = column − previous
//! column − 1; columns are sorted and distinct) and each entry hit more than once takes the next
//! count byte, `hits − 2` (255 escapes to a 4-byte count). Most entries are hit once and lie
//! near the previous one, so an entry takes 1–2 bytes instead of 8 (u32 column + f32 weight).
//! Decoding rebuilds the very f32 the builder used to store (`hits as f32 / K_i as f32`), so
//! every sum is bit-identical.
//!
//! Why two streams: the counts are read without a branch on the flag (a repeated hit is a coin
//! toss in small scenes; a mispredicted branch per entry made sweeps 2.5–3× slower than f32
//! rows), and the step's length branch is well predicted. The varint is written here rather
//! than taken from a crate for that layout: it is decoded inline in the solvers' sweeps.

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

/// Monte Carlo rows as ray counts, varint-coded (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct CountRows {
    /// Row `i` is `bytes[row_start[i]..row_start[i+1]]` (u64: rows of large bakes pass 4 GiB).
    row_start: Vec<u64>,
    /// Gathering rays `K_i` of each row: the denominator of its weights.
    rays: Vec<u32>,
    /// The rows, then one padding byte: a step's second byte is read before its first says
    /// whether there is one.
    bytes: Vec<u8>,
    entries: u64,
}

impl Default for CountRows {
    fn default() -> CountRows {
        CountRows {
            row_start: vec![0],
            rays: Vec::new(),
            bytes: vec![0],
            entries: 0,
        }
    }
}

impl CountRows {
    /// Appends a row from the source texels its `rays` rays hit, sorted (a texel hit `n` times
    /// appears `n` times).
    pub fn push_row(&mut self, sorted_hits: &[u32], rays: u32) {
        let runs = || sorted_hits.chunk_by(|a, b| a == b);
        self.bytes.pop(); // the padding
        if !sorted_hits.is_empty() {
            let count_bytes = |hits: usize| match hits {
                1 => 0,
                2..=256 => 1,
                _ => 5,
            };
            write_varint(&mut self.bytes, runs().map(|r| count_bytes(r.len())).sum());
            for run in runs().filter(|r| r.len() > 1) {
                match u8::try_from(run.len() - 2) {
                    Ok(b) if b < ESCAPE => self.bytes.push(b),
                    _ => {
                        self.bytes.push(ESCAPE);
                        self.bytes.extend((run.len() as u32).to_le_bytes());
                    }
                }
            }
            let mut previous = u32::MAX; // the first gap counts from column 0
            for run in runs() {
                let gap = run[0].wrapping_sub(previous).wrapping_sub(1) as u64;
                write_varint(&mut self.bytes, gap << 1 | (run.len() > 1) as u64);
                previous = run[0];
                self.entries += 1;
            }
        }
        self.row_start.push(self.bytes.len() as u64);
        self.bytes.push(0);
        self.rays.push(rays);
    }

    /// Empties the last row (its ray count stays).
    pub fn clear_last_row(&mut self) {
        let n = self.rays.len();
        if n == 0 {
            return;
        }
        let start = self.row_start[n - 1];
        let removed = self.row(n - 1).count() as u64;
        self.entries -= removed;
        self.bytes.truncate(start as usize);
        self.bytes.push(0);
        self.row_start[n] = start;
    }

    /// Appends the rows of `other` after these.
    pub fn append(&mut self, other: CountRows) {
        let base = *self.row_start.last().unwrap();
        self.row_start
            .extend(other.row_start[1..].iter().map(|s| s + base));
        self.rays.extend(other.rays);
        self.bytes.pop();
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
        let rays = self.rays[i] as f32;
        let (start, end) = (self.row_start[i] as usize, self.row_start[i + 1] as usize);
        // From the row's start to the padding byte.
        let bytes = &self.bytes[start..];
        let (counts, next) = match end > start {
            true => {
                let (m, header) = read_varint(bytes, 0);
                (header, header + m as usize)
            }
            false => (0, 0),
        };
        CountRow {
            bytes,
            end: end - start,
            counts,
            next,
            col: u32::MAX,
            rays,
            once: 1.0 / rays,
        }
    }
}

/// The count byte that says a 4-byte count (little-endian `hits`) follows.
const ESCAPE: u8 = 255;

fn write_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// The varint at `bytes[at..]` and the position after it.
#[inline]
fn read_varint(bytes: &[u8], at: usize) -> (u64, usize) {
    let b = bytes[at];
    if b < 0x80 {
        return (b as u64, at + 1);
    }
    read_varint_tail(bytes, at)
}

#[cold]
fn read_varint_tail(bytes: &[u8], mut at: usize) -> (u64, usize) {
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
    /// From the row's start to the end of the storage (its padding byte included).
    bytes: &'a [u8],
    /// The row's end in `bytes`.
    end: usize,
    /// Position of the next count byte.
    counts: usize,
    /// Position of the next step.
    next: usize,
    /// The previous entry's column (`u32::MAX` before the first).
    col: u32,
    rays: f32,
    /// `1 / K_i`: the weight of a single hit, equal to `1 as f32 / K_i`.
    once: f32,
}

impl Iterator for CountRow<'_> {
    type Item = (u32, f32);

    /// The solvers' path: the decoder's state in locals for the whole row.
    #[inline]
    fn fold<B, F: FnMut(B, (u32, f32)) -> B>(self, init: B, mut f: F) -> B {
        let mut acc = init;
        for entry in self {
            acc = f(acc, entry);
        }
        acc
    }

    #[inline(always)]
    fn next(&mut self) -> Option<(u32, f32)> {
        if self.next >= self.end {
            return None;
        }
        // A one- or two-byte step without a branch on its length (in small scenes most steps
        // take one byte, in large ones most take two); longer ones are rare.
        let (b0, b1) = (self.bytes[self.next], self.bytes[self.next + 1]);
        let v = if (b0 & b1) >= 0x80 {
            let (v, next) = read_varint_tail(self.bytes, self.next);
            self.next = next;
            v
        } else {
            let long = (b0 >> 7) as u64;
            self.next += 1 + long as usize;
            (b0 & 0x7f) as u64 | (((b1 as u64) << 7) * long)
        };
        self.col = self.col.wrapping_add((v >> 1) as u32).wrapping_add(1);
        // Read whether or not the entry is repeated (`counts` < `next` ≤ len: in bounds), so
        // that no branch depends on the flag.
        let repeated = (v & 1) as usize;
        let byte = self.bytes[self.counts];
        let hits = if (repeated == 1) & (byte == ESCAPE) {
            self.escaped_count()
        } else {
            byte as u32 + 2
        };
        self.counts += repeated;
        let weight = hits as f32 / self.rays;
        Some((self.col, if repeated == 1 { weight } else { self.once }))
    }
}

impl CountRow<'_> {
    /// The 4-byte count after an escape byte at `counts`; moves past it.
    #[cold]
    fn escaped_count(&mut self) -> u32 {
        let at = self.counts + 1;
        self.counts += 4;
        u32::from_le_bytes(self.bytes[at..at + 4].try_into().unwrap())
    }
}

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

    /// A bake's Monte Carlo rows stored as counts and the same bake's f32 rows (the default)
    /// hold the same weights and give bit-identical solutions with every row solver.
    #[test]
    fn solutions_are_identical_with_counts_and_weights() {
        use crate::config::{BakeConfig, RowSolver};
        use crate::transport::Transport;
        use crate::{NoProgress, compute, solve};
        let mut c = BakeConfig::draft();
        c.auto = None;
        c.transport.gather_rays = 128;
        let fixture = crate::solve::tests::fixture("cornell_box.gltf");
        let f32_baked = compute(&fixture, &c, &NoProgress).unwrap();
        c.transport.count_rows = true;
        let baked = compute(&fixture, &c, &NoProgress).unwrap();
        let counts = &baked.transport;
        assert!(matches!(counts.rows, Rows::Counts(_)) && counts.rows.entries() > 0);
        assert_eq!(
            f32_baked.transport.rows,
            Rows::Weights(counts.rows.to_weights())
        );
        let weights = Transport {
            rows: f32_baked.transport.rows.clone(),
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
                assert!(b.irradiance == f32_baked.solution.irradiance);
            }
        }
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
