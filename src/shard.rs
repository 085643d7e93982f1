//! Per-item work divided among the processes of a bake.
//!
//! A distributed bake ([`crate::distributed`]) runs every stage on every process, but the
//! stages that cast rays per item (the validity pass per texel, the planner's point samples, the
//! punctual light per texel) compute only this process's part of the items and then gather
//! everyone's, so each process ends with the whole result. Results travel as `f32`s
//! ([`Packed`]), bit for bit, and each item's value depends only on its index and seed, so the
//! gathered result is the one a single process computes. On one process ([`Alone`]) [`map`]
//! is a plain parallel map.

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use crate::Result;

/// The processes sharing a bake's per-item work.
pub(crate) trait Shards {
    /// How many processes share the work.
    fn count(&self) -> usize;
    /// The items of `0..n` this process computes: process `p` of `P` takes `n·p/P .. n·(p+1)/P`.
    fn part(&self, n: usize) -> Range<usize>;
    /// Every process's `mine` concatenated in process order (`len` values in all), with the
    /// sum of everyone's `rays`.
    fn gather(&self, mine: Vec<f32>, rays: u64, len: usize) -> Result<(Vec<f32>, u64)>;
}

/// One process: its part is everything.
pub(crate) struct Alone;

impl Shards for Alone {
    fn count(&self) -> usize {
        1
    }

    fn part(&self, n: usize) -> Range<usize> {
        0..n
    }

    fn gather(&self, mine: Vec<f32>, rays: u64, _len: usize) -> Result<(Vec<f32>, u64)> {
        Ok((mine, rays))
    }
}

/// Process `p` of `processes`' part of `0..n`.
pub(crate) fn part_of(p: usize, processes: usize, n: usize) -> Range<usize> {
    n * p / processes..n * (p + 1) / processes
}

/// A value that travels between processes as [`Packed::FLOATS`] `f32`s, unchanged.
pub(crate) trait Packed: Sized {
    const FLOATS: usize;
    fn pack(&self, out: &mut Vec<f32>);
    fn unpack(values: &[f32]) -> Self;
}

/// `f` over `0..n`, each process computing its part: the same vector on every process, and the
/// one a single process computes.
pub(crate) fn map<T, F>(shards: &dyn Shards, n: usize, f: F) -> Result<Vec<T>>
where
    T: Packed + Send,
    F: Fn(usize) -> T + Sync + Send,
{
    if shards.count() == 1 {
        return Ok((0..n).into_par_iter().map(f).collect());
    }
    let mine: Vec<T> = shards.part(n).into_par_iter().map(f).collect();
    let mut packed = Vec::with_capacity(mine.len() * T::FLOATS);
    for v in &mine {
        v.pack(&mut packed);
    }
    let (all, _) = shards.gather(packed, 0, n * T::FLOATS)?;
    Ok(all.chunks_exact(T::FLOATS).map(T::unpack).collect())
}

impl Packed for Vec3 {
    const FLOATS: usize = 3;
    fn pack(&self, out: &mut Vec<f32>) {
        out.extend_from_slice(&self.to_array());
    }
    fn unpack(values: &[f32]) -> Self {
        Vec3::from_slice(values)
    }
}

/// A `bool` as 0 or 1.
pub(crate) fn flag(b: bool) -> f32 {
    if b { 1.0 } else { 0.0 }
}

/// A `u32` carried in an `f32`'s bits (exactly; the values are only copied, never computed with).
pub(crate) fn bits(v: u32) -> f32 {
    f32::from_bits(v)
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;

    use super::*;

    /// Two processes in one: process 1's part is computed first and handed to process 0's
    /// gather, as an exchange would.
    struct Pair {
        process: usize,
        other: RefCell<Option<Vec<f32>>>,
    }

    impl Shards for Pair {
        fn count(&self) -> usize {
            2
        }
        fn part(&self, n: usize) -> Range<usize> {
            part_of(self.process, 2, n)
        }
        fn gather(&self, mine: Vec<f32>, rays: u64, len: usize) -> Result<(Vec<f32>, u64)> {
            let other = self.other.borrow_mut().take().unwrap_or_default();
            let all = match self.process {
                0 => [mine.clone(), other].concat(),
                _ => [other, mine.clone()].concat(),
            };
            *self.other.borrow_mut() = Some(mine);
            assert!(self.process == 1 || all.len() == len);
            Ok((all, rays))
        }
    }

    #[test]
    fn a_sharded_map_equals_the_whole_one() {
        let f = |i: usize| Vec3::new(i as f32, (i as f32).sqrt(), f32::from_bits(i as u32));
        for n in [0, 1, 7, 1000] {
            let whole = map(&Alone, n, f).unwrap();
            let second = Pair {
                process: 1,
                other: RefCell::new(None),
            };
            map(&second, n, f).unwrap(); // records process 1's part
            let first = Pair {
                process: 0,
                other: second.other,
            };
            let sharded = map(&first, n, f).unwrap();
            let same = whole.len() == sharded.len()
                && (whole.iter().zip(&sharded))
                    .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits));
            assert!(same, "n = {n}");
        }
    }
}
