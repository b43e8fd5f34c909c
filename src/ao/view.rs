//! View-dependent AO (issue #46): the AO voxels one image reads, so that LAO and CAO
//! compute only those and the image stays exact.
//!
//! A pixel of the ray caster depends on the AO volume only through `shade`'s one
//! trilinear read per contributing sample: at `ao_at`, the sample moved up to
//! [`crate::sample::AO_READ_REACH`] voxels off the surface along its normal (or back
//! along the ray on a cut face). Which samples contribute — those of non-zero opacity
//! up to early termination, behind the clip shapes' test and the segments' weights — and
//! where `ao_at` lies depend on the density, the transfer function, clipping, modulation,
//! surfaces, the camera, step and jitter, never on the AO values: AO scales a sample's
//! colour, not its opacity. So one ray cast with the frame's own pipeline that marks the
//! footprint of every AO read instead of reading it (the *visibility pass*:
//! `MARK_AO` in `shaders/raycast.wgsl`, [`ViewMarks`] in the CPU twin) gives exactly the
//! voxels whose AO the image reads; every other voxel's AO can be anything. The
//! footprint is the 2×2×2 texels a trilinear read weighs, widened by
//! [`crate::sample::FOOTPRINT_SLACK`] of a texel either side for a sampler's fixed-point
//! weights (docs/algorithms.md, "View-dependent AO").

use crate::sample::trilinear_footprint;
use glam::Vec3;
use std::sync::atomic::{AtomicU32, Ordering};

/// Which voxels a visibility pass marks around each AO read. Only
/// [`Footprint::Trilinear`] keeps images exact; the others exist so that tests can show
/// that exactness rests on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Footprint {
    /// The texels a trilinear read weighs (with slack): exact.
    #[default]
    Trilinear,
    /// Only the texel nearest the read: one voxel too small.
    Nearest,
    /// The trilinear footprint of the sample itself, ignoring the AO read offset.
    AtSample,
}

impl Footprint {
    /// The code the shader reads (`extras.marks.x`).
    pub fn code(self) -> u32 {
        match self {
            Footprint::Trilinear => 0,
            Footprint::Nearest => 1,
            Footprint::AtSample => 2,
        }
    }
}

/// One bit per voxel of a volume of `dims` (x fastest): the voxels an image reads the
/// AO of.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViewMask {
    pub dims: [usize; 3],
    /// Bit `i % 32` of word `i / 32` for voxel `i`.
    pub words: Vec<u32>,
}

impl ViewMask {
    /// No voxel marked.
    pub fn empty(dims: [usize; 3]) -> Self {
        ViewMask {
            dims,
            words: vec![0; words_for(dims)],
        }
    }

    /// The mask read back from the GPU (`words` may be padded).
    pub fn from_words(dims: [usize; 3], mut words: Vec<u32>) -> Self {
        words.resize(words_for(dims), 0);
        ViewMask { dims, words }
    }

    /// Whether voxel `i` (linear, x fastest) is marked.
    pub fn contains(&self, i: usize) -> bool {
        self.words[i / 32] & (1 << (i % 32)) != 0
    }

    /// How many voxels are marked.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// Marks every voxel `other` marks too.
    pub fn union(&mut self, other: &ViewMask) {
        assert_eq!(self.dims, other.dims, "view masks of different volumes");
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
    }

    /// Per brick of `edge` voxels (x fastest over the bricks): whether it holds a marked
    /// voxel.
    pub fn bricks(&self, edge: usize) -> Vec<bool> {
        let d = self.dims;
        let grid = d.map(|n| n.div_ceil(edge).max(1));
        let mut out = vec![false; grid.iter().product()];
        for (w, &word) in self.words.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let i = w * 32 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let v = crate::volume::voxel_of(i, d).map(|c| c / edge);
                out[v[0] + grid[0] * (v[1] + grid[1] * v[2])] = true;
            }
        }
        out
    }
}

/// Words of a mask of a volume of `dims`.
pub fn words_for(dims: [usize; 3]) -> usize {
    dims.iter().product::<usize>().div_ceil(32).max(1)
}

/// A [`ViewMask`] being marked by the CPU twin's ray cast (on rayon threads).
#[derive(Debug)]
pub struct ViewMarks {
    dims: [usize; 3],
    words: Vec<AtomicU32>,
    footprint: Footprint,
}

impl Clone for ViewMarks {
    fn clone(&self) -> Self {
        ViewMarks {
            dims: self.dims,
            words: self
                .words
                .iter()
                .map(|w| AtomicU32::new(w.load(Ordering::Relaxed)))
                .collect(),
            footprint: self.footprint,
        }
    }
}

impl ViewMarks {
    pub fn new(dims: [usize; 3], footprint: Footprint) -> Self {
        ViewMarks {
            dims,
            words: (0..words_for(dims)).map(|_| AtomicU32::new(0)).collect(),
            footprint,
        }
    }

    /// Marks the voxels an AO read at `ao_at` for the sample at `sample` weighs (the
    /// twin of `mark_ao` in `shaders/raycast.wgsl`).
    pub fn mark(&self, sample: Vec3, ao_at: Vec3) {
        let d = self.dims;
        let [x, y, z] = match self.footprint {
            Footprint::Trilinear => trilinear_footprint(d, ao_at),
            Footprint::AtSample => trilinear_footprint(d, sample),
            Footprint::Nearest => {
                let c = ao_at * Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
                let n = [0, 1, 2].map(|a| (c[a].floor().max(0.0) as usize).min(d[a] - 1));
                [[n[0]; 2], [n[1]; 2], [n[2]; 2]]
            }
        };
        for k in z[0]..=z[1] {
            for j in y[0]..=y[1] {
                for i in x[0]..=x[1] {
                    let v = i + d[0] * (j + d[1] * k);
                    self.words[v / 32].fetch_or(1 << (v % 32), Ordering::Relaxed);
                }
            }
        }
    }

    pub fn into_mask(self) -> ViewMask {
        ViewMask {
            dims: self.dims,
            words: self.words.into_iter().map(AtomicU32::into_inner).collect(),
        }
    }
}
