//! How stored rows are held in memory: f32 form factors, or — for Monte Carlo rows — the exact
//! ray counts they come from.
//!
//! A Monte Carlo entry is `F_ij = hits_ij / K_i` (hits of texel `j` among the `K_i` rays of
//! texel `i`), so a row is stored losslessly as `K_i` and, per entry, the step from the previous
//! column and the hit count. A non-empty row's bytes are three streams after a header (an
//! empty row has no bytes, and no `K_i`: its weights are never read):
//!
//! ```text
//!   varint(entries) · varint(far bytes) · varint(K_i) · steps (1 byte per entry) · far · counts
//! ```
//!
//! Rows are found by their start in the bytes, a u16 offset per row (u32 once any group's rows
//! pass 64 KiB) from a u64 base every 32 rows: short rows are common (most of a large scene's
//! texels see few others, many none), and a u64 start and u32 `K_i` per row were a fifth of
//! their bytes.
//!
//! With `gap` = column − previous column − 1 (columns are sorted and distinct; the first gap
//! counts from column 0), an entry's step byte is `far << 7 | (gap & 63) << 1 | repeated`.
//! `far` says `gap ≥ 64`: the next far byte holds `gap >> 6` (255 escapes to 4 bytes,
//! little-endian). `repeated` says the entry was hit more than once: the next count byte holds
//! `hits − 1` (255 escapes to `hits` in 4 bytes). Most entries are hit once and lie near the
//! previous one, so an entry takes 1–2 bytes instead of 8 (u32 column + f32 weight).
//! Decoding rebuilds the very f32 the builder used to store (`hits as f32 / K_i as f32`), so
//! every sum is bit-identical.
//!
//! Why this layout: a sweep's sum over f32 rows is paced by its chain of adds (one per entry),
//! and the decoding must fit beside it. Entry `k`'s step byte sits at a fixed place
//! (`steps[k]`), and the far and count streams advance by a flag of that byte, never by a byte
//! read from their own stream, so no load waits for the previous entry's. The sweeps
//! ([`CountRow::fold`]) decode 16 entries at a time before summing them: the near gaps
//! vectorise, the flags of the block are gathered into bit masks by a multiply, and whether a
//! block has any far or repeated entry is a predictable branch (most blocks of a small scene
//! have repeated ones, most of a large one far ones) while which entries do is read without a
//! branch (a repeated hit is a coin toss). The far and count bytes are therefore read whether or
//! not the flags ask for them, and the storage ends in a padding byte. The previous layout, a
//! varint per step decoded entry by entry (its state in memory behind a cold call, branches on
//! the flags), swept 2.4–3× slower than f32 rows; this one 1.4–2.1× (Gauss–Seidel; Jacobi
//! 1.9–2.7×; the guide's "Accuracy and speed", "Memory"). The streams are written here rather than taken from a crate:
//! they are decoded inline in the solvers' sweeps.

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
    /// Where row `i` begins in `bytes`: `base[i / GROUP] + start[i]` (`start` has one more
    /// entry than there are rows: the last row's end).
    start: Starts,
    base: Vec<u64>,
    /// The rows, then one padding byte: the far and count bytes are read before the step
    /// byte's flags say whether they are there.
    bytes: Vec<u8>,
    entries: u64,
}

/// Row starts relative to their group's base: u16 while every group's rows fit in 64 KiB
/// (rows of up to ~2000 rays), else u32 for all. A u64 per row, as before, was a sixth of a
/// short row's bytes; the offsets are relative because rows of large bakes pass 4 GiB.
#[derive(Clone, Debug, PartialEq)]
enum Starts {
    Narrow(Vec<u16>),
    Wide(Vec<u32>),
}

impl Default for CountRows {
    fn default() -> CountRows {
        CountRows {
            start: Starts::Narrow(vec![0]),
            base: vec![0],
            bytes: vec![0],
            entries: 0,
        }
    }
}

/// Rows sharing one u64 base offset. A row takes at most 15 header bytes and 11 per ray
/// (`gather_rays` ≤ 2^20, [`crate::config`]), so a group spans less than 4 GiB: the u32
/// offsets always fit.
const GROUP: usize = 32;

/// Gaps below this fit in a step byte; larger ones put `gap >> GAP_BITS` in the far stream.
const GAP_BITS: u32 = 6;
const NEAR_GAPS: u32 = 1 << GAP_BITS;

/// A far or count byte that says a 4-byte value (little-endian) follows.
const ESCAPE: u8 = 255;

/// Bytes of `v` in a far or count stream: one byte below [`ESCAPE`], else the escape and 4.
fn escaped_len(v: u32) -> usize {
    match v < ESCAPE as u32 {
        true => 1,
        false => 5,
    }
}

fn write_escaped(out: &mut Vec<u8>, v: u32) {
    match u8::try_from(v) {
        Ok(b) if b < ESCAPE => out.push(b),
        _ => {
            out.push(ESCAPE);
            out.extend(v.to_le_bytes());
        }
    }
}

impl CountRows {
    /// Appends a row from the source texels its `rays` rays hit, sorted (a texel hit `n` times
    /// appears `n` times).
    pub(crate) fn push_row(&mut self, sorted_hits: &[u32], rays: u32) {
        // (column, hits) of each entry, and its gap from the previous column.
        let runs = || sorted_hits.chunk_by(|a, b| a == b);
        let gaps = || {
            let mut previous = u32::MAX; // the first gap counts from column 0
            runs().map(move |run| {
                let gap = run[0].wrapping_sub(previous).wrapping_sub(1);
                previous = run[0];
                (gap, run.len() as u32)
            })
        };
        self.bytes.pop(); // the padding
        if !sorted_hits.is_empty() {
            let (mut entries, mut far_bytes) = (0u64, 0);
            for (gap, _) in gaps() {
                entries += 1;
                if gap >= NEAR_GAPS {
                    far_bytes += escaped_len(gap >> GAP_BITS);
                }
            }
            write_varint(&mut self.bytes, entries);
            write_varint(&mut self.bytes, far_bytes as u64);
            write_varint(&mut self.bytes, rays as u64);
            for (gap, hits) in gaps() {
                let far = (gap >= NEAR_GAPS) as u8;
                let near = (gap % NEAR_GAPS) as u8;
                self.bytes.push(far << 7 | near << 1 | (hits > 1) as u8);
            }
            for (gap, _) in gaps().filter(|&(gap, _)| gap >= NEAR_GAPS) {
                write_escaped(&mut self.bytes, gap >> GAP_BITS);
            }
            for (_, hits) in gaps().filter(|&(_, hits)| hits > 1) {
                match u8::try_from(hits - 1) {
                    Ok(b) if b < ESCAPE => self.bytes.push(b),
                    _ => {
                        self.bytes.push(ESCAPE);
                        self.bytes.extend(hits.to_le_bytes());
                    }
                }
            }
            self.entries += entries;
        }
        self.push_start(self.bytes.len() as u64);
        self.bytes.push(0);
    }

    /// Appends the end of the last row (the next one's start), at `at` in `bytes`.
    fn push_start(&mut self, at: u64) {
        let n = self.start_len();
        if n.is_multiple_of(GROUP) {
            self.base.push(at);
        }
        let relative = at - self.base.last().unwrap();
        let relative = u32::try_from(relative).expect("a group of count rows within 4 GiB");
        if let Starts::Narrow(narrow) = &mut self.start {
            match u16::try_from(relative) {
                Ok(r) => return narrow.push(r),
                Err(_) => self.start = Starts::Wide(narrow.iter().map(|&r| r as u32).collect()),
            }
        }
        if let Starts::Wide(wide) = &mut self.start {
            wide.push(relative);
        }
    }

    /// Entries of `start` (rows + 1).
    fn start_len(&self) -> usize {
        match &self.start {
            Starts::Narrow(s) => s.len(),
            Starts::Wide(s) => s.len(),
        }
    }

    /// Drops the last entry of `start` (and its group's base if it began one).
    fn pop_start(&mut self) {
        match &mut self.start {
            Starts::Narrow(s) => _ = s.pop(),
            Starts::Wide(s) => _ = s.pop(),
        }
        if self.start_len().is_multiple_of(GROUP) {
            self.base.pop();
        }
    }

    /// Where row `i` begins in `bytes` (`i` = rows: where the last one ends). Which offsets
    /// are held is the same for every row: a predicted branch.
    #[inline(always)]
    fn start(&self, i: usize) -> usize {
        let relative = match &self.start {
            Starts::Narrow(s) => s[i] as u64,
            Starts::Wide(s) => s[i] as u64,
        };
        (self.base[i / GROUP] + relative) as usize
    }

    /// Empties the last row.
    pub(crate) fn clear_last_row(&mut self) {
        let n = self.len();
        if n == 0 {
            return;
        }
        let start = self.start(n - 1);
        let removed = self.row(n - 1).len() as u64;
        self.entries -= removed;
        self.bytes.truncate(start);
        self.bytes.push(0);
        self.pop_start();
        self.push_start(start as u64);
    }

    /// Appends the rows of `other` after these.
    pub(crate) fn append(&mut self, other: CountRows) {
        let at = self.start(self.len()) as u64;
        for i in 1..other.start_len() {
            self.push_start(at + other.start(i) as u64);
        }
        self.bytes.pop();
        self.bytes.extend(other.bytes);
        self.entries += other.entries;
    }

    /// Rows held.
    pub(crate) fn len(&self) -> usize {
        self.start_len() - 1
    }
    pub(crate) fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The entries of row `i` as (source texel, `hits / K_i`). Not inlined: its header's
    /// varints would keep [`Rows::row`] from being inlined into the f32 rows' sweeps.
    #[inline(never)]
    pub(crate) fn row(&self, i: usize) -> CountRow<'_> {
        let (start, end) = (self.start(i), self.start(i + 1));
        let (entries, far_bytes, rays, steps) = match end > start {
            true => {
                let (entries, at) = read_varint(&self.bytes, start);
                let (far_bytes, at) = read_varint(&self.bytes, at);
                let (rays, at) = read_varint(&self.bytes, at);
                (entries as usize, far_bytes as usize, rays as f32, at)
            }
            // An empty row's weights are never read.
            false => (0, 0, 1.0, start),
        };
        let far = steps + entries;
        CountRow {
            steps: self.bytes[steps..far].iter(),
            // From the far stream to the padding byte.
            tail: &self.bytes[far..],
            far: 0,
            counts: far_bytes,
            col: u32::MAX,
            rays,
        }
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
#[inline]
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
    /// The step bytes of the entries not read yet.
    steps: Iter<'a, u8>,
    /// From the row's far stream to the end of the storage (its padding byte included).
    tail: &'a [u8],
    /// Position of the next far byte in `tail`.
    far: usize,
    /// Position of the next count byte in `tail`.
    counts: usize,
    /// The previous entry's column (`u32::MAX` before the first).
    col: u32,
    /// `K_i` as f32: an entry's weight is `hits as f32 / rays`, as the builder's was.
    rays: f32,
}

/// Decodes the entry whose step byte is `step` from a row's far and count streams (`tail`,
/// next bytes at `far` and `counts`), after the entry at column `col`: its column and weight.
/// A free function over the decoder's state, so that the sweeps keep it in registers.
#[inline(always)]
fn decode(
    step: u8,
    tail: &[u8],
    far: &mut usize,
    counts: &mut usize,
    col: &mut u32,
    rays: f32,
) -> (u32, f32) {
    // The flags as masks, not branches: whether an entry is far or repeated is often a coin
    // toss, and a mispredicted branch costs more than the entry's whole sum. The far and count
    // bytes are read either way (in bounds: both positions are below the padding byte's).
    let far_mask = 0u8.wrapping_sub(step >> 7);
    let repeated = (step & 1) as usize;
    let mut high = (tail[*far] & far_mask) as u32;
    if high == ESCAPE as u32 {
        high = escaped(tail, *far);
        *far += 4;
    }
    *far += (step >> 7) as usize;
    *col = col
        .wrapping_add(high << GAP_BITS | ((step >> 1) as u32 % NEAR_GAPS))
        .wrapping_add(1);
    // `hits − 1`, or 0 for a single hit.
    let count = tail[*counts] & 0u8.wrapping_sub(step & 1);
    let hits = if count == ESCAPE {
        let hits = escaped(tail, *counts);
        *counts += 4;
        hits
    } else {
        count as u32 + 1
    };
    *counts += repeated;
    (*col, hits as f32 / rays)
}

/// A row's far and count streams as [`CountRow::fold`] reads them, a block at a time.
struct BlockDecoder<'a> {
    tail: &'a [u8],
    far: usize,
    counts: usize,
    rays: f32,
    once: f32,
}

impl BlockDecoder<'_> {
    /// The column steps (`gap + 1`) and weights of the [`BLOCK`] entries whose step bytes are
    /// `block`.
    #[inline(always)]
    fn block(&mut self, block: &[u8; BLOCK]) -> ([u32; BLOCK], [f32; BLOCK]) {
        let tail = self.tail;
        // Column steps of near gaps (vectorised), then the far ones' high bits.
        let mut delta = [0u32; BLOCK];
        for (d, &step) in delta.iter_mut().zip(block) {
            *d = ((step >> 1) as u32 % NEAR_GAPS) + 1;
        }
        // Whether a block has far or repeated entries is predictable (most blocks of a small
        // scene have repeated ones, most of a large one far ones); which entries are is not,
        // so they are read without a branch on the flag.
        let (far_flags, repeated_flags) = flags(block);
        if far_flags != 0 {
            for (d, &step) in delta.iter_mut().zip(block) {
                let is_far = (step >> 7) as u32;
                let mut high = tail[self.far] as u32 & 0u32.wrapping_sub(is_far);
                if high == ESCAPE as u32 {
                    high = escaped(tail, self.far);
                    self.far += 4;
                }
                self.far += is_far as usize;
                *d = d.wrapping_add(high << GAP_BITS);
            }
        }
        let mut weight = [self.once; BLOCK];
        if repeated_flags != 0 {
            for (w, &step) in weight.iter_mut().zip(block) {
                let repeated = (step & 1) as u32;
                // `hits − 1`, or 0 for a single hit (whose weight is `1 / K_i` too).
                let count = tail[self.counts] as u32 & 0u32.wrapping_sub(repeated);
                let hits = if count == ESCAPE as u32 {
                    self.counts += 4;
                    escaped(tail, self.counts - 4)
                } else {
                    count + 1
                };
                self.counts += repeated as usize;
                *w = hits as f32 / self.rays;
            }
        }
        (delta, weight)
    }
}

/// Entries decoded together by [`CountRow::fold`].
const BLOCK: usize = 16;

/// The far flags (bit 7) and the repeated flags (bit 0) of a block's step bytes, as bit `k`
/// for entry `k`: each byte's bit gathered into the top byte by a multiply.
#[inline(always)]
fn flags(block: &[u8; BLOCK]) -> (u32, u32) {
    const LOW_BITS: u64 = 0x0101_0101_0101_0101;
    const GATHER: u64 = 0x0102_0408_1020_4080; // byte i's bit 0 to bit 56 + i
    let gather = |x: u64| (x & LOW_BITS).wrapping_mul(GATHER) >> 56;
    let (mut far, mut repeated) = (0, 0);
    for (half, bytes) in block.chunks_exact(8).enumerate() {
        let x = u64::from_le_bytes(bytes.try_into().unwrap());
        far |= (gather(x >> 7) as u32) << (8 * half);
        repeated |= (gather(x) as u32) << (8 * half);
    }
    (far, repeated)
}

/// The 4-byte value after the escape byte at `tail[at]`.
#[cold]
fn escaped(tail: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(tail[at + 1..at + 5].try_into().unwrap())
}

impl Iterator for CountRow<'_> {
    type Item = (u32, f32);

    /// The solvers' path: `BLOCK` entries at a time, their columns and weights decoded
    /// before they are summed, so that the decoding runs ahead of the f32 sums (whose chain of
    /// adds sets the pace) and the flags cost a branch per block, not per entry.
    #[inline]
    fn fold<B, F: FnMut(B, (u32, f32)) -> B>(self, init: B, mut f: F) -> B {
        let CountRow {
            steps,
            tail,
            far,
            counts,
            mut col,
            rays,
        } = self;
        let mut decoder = BlockDecoder {
            tail,
            far,
            counts,
            rays,
            once: 1.0 / rays,
        };
        let mut acc = init;
        let mut blocks = steps.as_slice().chunks_exact(BLOCK);
        for block in &mut blocks {
            let (delta, weight) = decoder.block(block.try_into().unwrap());
            for (&d, &w) in delta.iter().zip(&weight) {
                col = col.wrapping_add(d);
                acc = f(acc, (col, w));
            }
        }
        // The last entries as a block padded with zero steps (near, single: they read
        // nothing), so that short rows decode as fast as long ones.
        let rest = blocks.remainder();
        if !rest.is_empty() {
            let mut block = [0u8; BLOCK];
            block[..rest.len()].copy_from_slice(rest);
            let (delta, weight) = decoder.block(&block);
            for (&d, &w) in delta.iter().zip(&weight).take(rest.len()) {
                col = col.wrapping_add(d);
                acc = f(acc, (col, w));
            }
        }
        acc
    }

    #[inline(always)]
    fn next(&mut self) -> Option<(u32, f32)> {
        let &step = self.steps.next()?;
        Some(decode(
            step,
            self.tail,
            &mut self.far,
            &mut self.counts,
            &mut self.col,
            self.rays,
        ))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.steps.size_hint()
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
    /// No rows.
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
                let start = match &c.start {
                    Starts::Narrow(s) => size(s.len(), 2),
                    Starts::Wide(s) => size(s.len(), 4),
                };
                start + size(c.base.len(), 8) + c.bytes.len() as u64
            }
        }
    }

    /// The entries of row `i` as (source texel, F_ij). Inlined into the sweeps: a call per
    /// row made f32 sweeps of short rows slower than before there were two storages.
    #[inline(always)]
    pub(crate) fn row(&self, i: usize) -> Row<'_> {
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
    /// A row of f32 weights: (source texel, form factor).
    Weights(Zip<Copied<Iter<'a, u32>>, Copied<Iter<'a, f32>>>),
    /// A row of ray counts.
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

    /// Rows across group bases, a row cleared whose end is a group's base, and a row whose bytes pass
    /// 64 KiB (the offsets widen to u32) all keep their entries.
    #[test]
    fn groups_and_wide_offsets_keep_rows() {
        let mut rows = CountRows::default();
        let mut expected: Vec<Vec<u32>> = Vec::new();
        let push = |rows: &mut CountRows, expected: &mut Vec<_>, hits: Vec<u32>| {
            rows.push_row(&hits, 8);
            expected.push(hits);
        };
        for i in 0..2 * GROUP as u32 {
            push(&mut rows, &mut expected, vec![i, i + 100, i + 100]);
        }
        rows.clear_last_row(); // its end is the third group's base
        *expected.last_mut().unwrap() = vec![];
        assert!(matches!(rows.start, Starts::Narrow(_)));
        let far_apart = (0..70_000).map(|j| j * 100).collect();
        push(&mut rows, &mut expected, far_apart);
        assert!(matches!(rows.start, Starts::Wide(_)));
        let mut more = CountRows::default();
        more.push_row(&[3], 8);
        rows.append(more);
        expected.push(vec![3]);
        let rows = Rows::Counts(rows);
        assert_eq!(rows.len(), expected.len());
        for (i, hits) in expected.iter().enumerate() {
            let mut want: Vec<(u32, f32)> = hits
                .chunk_by(|a, b| a == b)
                .map(|run| (run[0], run.len() as f32 / 8.0))
                .collect();
            want.dedup();
            assert_eq!(rows.row(i).collect::<Vec<_>>(), want, "row {i}");
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
