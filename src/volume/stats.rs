//! Value statistics and histograms, in physical units, ignoring NaN/Inf voxels.

use super::{Volume, with_voxels};
use rayon::prelude::*;

/// Range and mean of the finite voxel values (physical units), and how many are not finite.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Stats {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    /// Voxels that are NaN or ±Inf (float types only). They are treated as empty.
    pub non_finite: u64,
    pub finite: u64,
}

#[derive(Clone, Copy)]
struct Acc {
    min: f64,
    max: f64,
    sum: f64,
    finite: u64,
    non_finite: u64,
}

impl Acc {
    const EMPTY: Acc = Acc {
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        sum: 0.0,
        finite: 0,
        non_finite: 0,
    };

    fn push(mut self, x: f64) -> Acc {
        if x.is_finite() {
            self.min = self.min.min(x);
            self.max = self.max.max(x);
            self.sum += x;
            self.finite += 1;
        } else {
            self.non_finite += 1;
        }
        self
    }

    fn merge(self, o: Acc) -> Acc {
        Acc {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
            sum: self.sum + o.sum,
            finite: self.finite + o.finite,
            non_finite: self.non_finite + o.non_finite,
        }
    }
}

/// Chunk size for parallel reductions: big enough that the f64 partial sums stay exact
/// for 8/16-bit data and per-chunk overhead is negligible.
const CHUNK: usize = 1 << 16;

impl Volume {
    /// Min, max and mean of the finite physical values. An all-NaN volume reports 0s.
    #[allow(
        clippy::unnecessary_cast,
        reason = "the cast is a no-op only for the f64 variant"
    )]
    pub fn stats(&self) -> Stats {
        let acc = with_voxels!(&self.data, v => v
            .par_chunks(CHUNK)
            .map(|c| c.iter().fold(Acc::EMPTY, |a, &x| a.push(x as f64)))
            .reduce(|| Acc::EMPTY, Acc::merge));
        // Scaling is linear, so apply it to the stored-value extremes and mean.
        let s = self.scaling;
        if acc.finite == 0 {
            return Stats {
                min: 0.0,
                max: 0.0,
                mean: 0.0,
                non_finite: acc.non_finite,
                finite: 0,
            };
        }
        let (a, b) = (s.apply(acc.min), s.apply(acc.max));
        Stats {
            min: a.min(b),
            max: a.max(b),
            mean: s.apply(acc.sum / acc.finite as f64),
            non_finite: acc.non_finite,
            finite: acc.finite,
        }
    }

    /// Histogram of the finite physical values over `[stats.min, stats.max]`.
    #[allow(
        clippy::unnecessary_cast,
        reason = "the cast is a no-op only for the f64 variant"
    )]
    pub fn histogram(&self, bins: usize, stats: &Stats) -> Histogram {
        let bins = bins.max(1);
        let (lo, hi) = (stats.min, stats.max);
        let width = if hi > lo {
            (hi - lo) / bins as f64
        } else {
            1.0
        };
        let s = self.scaling;
        let bin_of = move |x: f64| -> Option<usize> {
            let v = s.apply(x);
            if !v.is_finite() {
                return None;
            }
            Some((((v - lo) / width) as usize).min(bins - 1))
        };
        let counts = with_voxels!(&self.data, v => v
        .par_chunks(CHUNK)
        .map(|c| {
            let mut h = vec![0u64; bins];
            for &x in c {
                if let Some(b) = bin_of(x as f64) {
                    h[b] += 1;
                }
            }
            h
        })
        .reduce(
            || vec![0u64; bins],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        ));
        Histogram {
            min: lo,
            max: hi,
            counts,
        }
    }
}

/// Voxel counts in equal-width bins over `[min, max]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Histogram {
    pub min: f64,
    pub max: f64,
    pub counts: Vec<u64>,
}

impl Histogram {
    /// Lower edge of bin `i`.
    pub fn bin_start(&self, i: usize) -> f64 {
        self.min + (self.max - self.min) * i as f64 / self.counts.len() as f64
    }

    /// Text rendering for a terminal: one line per bin, bar length on a log scale so
    /// that the huge background peak of CT/MR data does not flatten everything else.
    pub fn to_text(&self, width: usize) -> String {
        let peak = self.counts.iter().copied().max().unwrap_or(0);
        let scale = ((peak + 1) as f64).ln().max(1e-9);
        let mut out = String::new();
        for (i, &c) in self.counts.iter().enumerate() {
            let len = (((c + 1) as f64).ln() / scale * width as f64).round() as usize;
            let len = if c > 0 { len.max(1) } else { 0 };
            out.push_str(&format!(
                "{:>12.4} | {:<width$} {}\n",
                self.bin_start(i),
                "#".repeat(len),
                c,
                width = width
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Scaling, VoxelData};

    #[test]
    fn stats_skip_non_finite_and_apply_scaling() {
        let data = vec![1.0f32, f32::NAN, 3.0, f32::INFINITY, 5.0, 7.0, -1.0, 0.0];
        let mut v = Volume::new([2, 2, 2], [1.0; 3], VoxelData::F32(data)).expect("valid");
        let s = v.stats();
        assert_eq!((s.min, s.max, s.non_finite, s.finite), (-1.0, 7.0, 2, 6));
        assert!((s.mean - 15.0 / 6.0).abs() < 1e-12);
        v.scaling = Scaling {
            slope: -2.0,
            inter: 1.0,
        };
        let s = v.stats();
        assert_eq!((s.min, s.max), (-13.0, 3.0));
        assert!((s.mean - (1.0 - 2.0 * 15.0 / 6.0)).abs() < 1e-12);
    }

    #[test]
    fn histogram_counts_every_finite_voxel() {
        let data: Vec<i16> = (0..1000).map(|i| (i % 100) as i16 - 50).collect();
        let v = Volume::new([10, 10, 10], [1.0; 3], VoxelData::I16(data)).expect("valid");
        let s = v.stats();
        let h = v.histogram(10, &s);
        assert_eq!(h.counts.iter().sum::<u64>(), 1000);
        assert_eq!(h.counts[0], 100);
        assert_eq!(h.counts[9], 100);
        assert!(h.to_text(20).lines().count() == 10);
    }
}
