//! The one row builder every transport method uses: receivers in fixed-size chunks built in
//! parallel (one progress tick and abort check per chunk), then concatenated in order into
//! [`Rows`]: f32 weights, or ray counts for Monte Carlo rows built with
//! `TransportParams::count_rows` (which a chunk builds in its `counts`). Chunk boundaries never depend on the thread count, so neither do
//! the rows.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use super::{CountRows, Rows, Transport, WeightRows};
use crate::{Error, Progress, Result};

/// Rows of one chunk of receivers, concatenated in order afterwards: weighted entries in
/// `col`, `f` (row lengths in `row_len`), or Monte Carlo rows in `counts`.
#[derive(Default)]
pub(crate) struct ChunkRows {
    pub(crate) row_len: Vec<u32>,
    pub(crate) col: Vec<u32>,
    pub(crate) f: Vec<f32>,
    pub(crate) counts: CountRows,
    pub(crate) escape: Vec<f32>,
    pub(crate) direct: Vec<Vec3>,
    /// `direct` by source, when split ([`Transport::direct_terms`]).
    pub(crate) terms: Vec<Vec3>,
    /// The punctual part of `direct` ([`Transport::punctual`]).
    pub(crate) punctual: Vec<Vec3>,
    pub(crate) rays: u64,
}

impl ChunkRows {
    /// Ends the row begun when `col` held `start` entries: its length, escape and direct light.
    pub(crate) fn end_row(&mut self, start: usize, escape: f32, direct: Vec3) {
        self.row_len.push((self.col.len() - start) as u32);
        self.escape.push(escape);
        self.direct.push(if direct.is_finite() {
            direct
        } else {
            Vec3::ZERO
        });
    }

    /// Drops the entries of the row begun at `start` (its escape and direct light stay): for
    /// the solvers that store no rows.
    pub(crate) fn forget_row(&mut self, start: usize) {
        self.col.truncate(start);
        self.f.truncate(start);
        if let Some(len) = self.row_len.last_mut() {
            *len = 0;
        }
        self.counts.clear_last_row();
    }
}

/// Chunks built in parallel before they are appended and dropped: the rows are never held twice
/// (the furnished interior at `high` peaked ~480 MB, one run's rows, above its steady state
/// while all chunks were kept until the end), and a wave is large enough that waiting for its
/// slowest chunk costs little.
const WAVE: usize = 256;

/// Builds the rows of `n` receivers: `rows(range, out)` appends one row per receiver of
/// `range`, in order, to `out`. `stage` names the progress stage.
pub(crate) fn build(
    n: usize,
    chunk: usize,
    stage: &str,
    progress: &dyn Progress,
    rows: impl Fn(Range<usize>, &mut ChunkRows) + Sync,
) -> Result<Transport> {
    let aborted = AtomicBool::new(false);
    progress.begin(stage, n as u64);
    let mut assembled = Assembled::new(n);
    let chunks = n.div_ceil(chunk);
    for wave in (0..chunks).step_by(WAVE) {
        let built: Vec<ChunkRows> = (wave..(wave + WAVE).min(chunks))
            .into_par_iter()
            .map(|c| {
                let mut out = ChunkRows::default();
                if aborted.load(Ordering::Relaxed) || progress.aborted() {
                    aborted.store(true, Ordering::Relaxed);
                    return out;
                }
                let range = c * chunk..((c + 1) * chunk).min(n);
                rows(range.clone(), &mut out);
                progress.advance(range.len() as u64);
                out
            })
            .collect();
        if aborted.load(Ordering::Relaxed) {
            progress.end();
            return Err(Error::Aborted);
        }
        built.into_iter().for_each(|c| assembled.append(c));
    }
    progress.end();
    Ok(assembled.finish())
}

/// The rows so far, in receiver order.
struct Assembled {
    weights: WeightRows,
    counts: CountRows,
    counted: bool,
    t: Transport,
}

impl Assembled {
    fn new(n: usize) -> Assembled {
        let mut weights = WeightRows {
            row_start: Vec::with_capacity(n + 1),
            col: Vec::new(),
            f: Vec::new(),
        };
        weights.row_start.push(0);
        Assembled {
            weights,
            counts: CountRows::default(),
            counted: false,
            t: Transport {
                escape: Vec::with_capacity(n),
                direct: Vec::with_capacity(n),
                ..Transport::default()
            },
        }
    }

    fn append(&mut self, c: ChunkRows) {
        if !c.counts.is_empty() {
            self.counted = true;
            self.counts.append(c.counts);
        } else if !self.counted {
            let mut start = *self.weights.row_start.last().unwrap();
            for len in c.row_len {
                start += len;
                self.weights.row_start.push(start);
            }
            self.weights.col.extend(c.col);
            self.weights.f.extend(c.f);
        }
        self.t.escape.extend(c.escape);
        self.t.direct.extend(c.direct);
        self.t.direct_terms.extend(c.terms);
        self.t.punctual.extend(c.punctual);
        self.t.rays += c.rays;
    }

    fn finish(mut self) -> Transport {
        // Whole or not at all: a builder that does not sample punctual lights leaves none.
        if self.t.punctual.len() != self.t.direct.len() {
            self.t.punctual = Vec::new();
        }
        self.t.rows = match self.counted {
            true => Rows::Counts(self.counts),
            false => Rows::Weights(self.weights),
        };
        self.t
    }
}
