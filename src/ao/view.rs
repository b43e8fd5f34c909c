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

/// What a visibility pass marks: around each AO read, `footprint`'s voxels, as cells of
/// `edge` voxels a side (1: voxels; [`Marking::BRICKS`]: bricks, all CAO's
/// frames need, with far fewer atomic writes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Marking {
    pub footprint: Footprint,
    pub edge: usize,
}

impl Marking {
    /// The voxels themselves.
    pub const VOXELS: Marking = Marking {
        footprint: Footprint::Trilinear,
        edge: 1,
    };
    /// The bricks holding them (`ao::sparse::BRICK` voxels a side; checked there).
    pub const BRICKS: Marking = Marking {
        footprint: Footprint::Trilinear,
        edge: 8,
    };
}

impl From<Footprint> for Marking {
    /// `footprint`'s voxels.
    fn from(footprint: Footprint) -> Self {
        Marking { footprint, edge: 1 }
    }
}

/// One bit per cell of `edge` voxels a side of a volume of `dims` (x fastest): the
/// cells holding a voxel whose AO an image reads.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViewMask {
    pub dims: [usize; 3],
    /// Cell edge in voxels (1: one bit per voxel).
    pub edge: usize,
    /// Bit `i % 32` of word `i / 32` for cell `i`.
    pub words: Vec<u32>,
}

impl ViewMask {
    /// No voxel marked.
    pub fn empty(dims: [usize; 3]) -> Self {
        ViewMask {
            dims,
            edge: 1,
            words: vec![0; words_for(dims, 1)],
        }
    }

    /// The mask read back from the GPU (`words` may be padded).
    pub fn from_words(dims: [usize; 3], edge: usize, mut words: Vec<u32>) -> Self {
        words.resize(words_for(dims, edge), 0);
        ViewMask { dims, edge, words }
    }

    /// Cells per axis.
    pub fn grid(&self) -> [usize; 3] {
        grid_of(self.dims, self.edge)
    }

    /// Whether voxel `i` (linear, x fastest) lies in a marked cell.
    pub fn contains(&self, i: usize) -> bool {
        let c = match self.edge {
            1 => i,
            e => {
                let v = crate::volume::voxel_of(i, self.dims).map(|c| c / e);
                let g = self.grid();
                v[0] + g[0] * (v[1] + g[1] * v[2])
            }
        };
        self.words[c / 32] & (1 << (c % 32)) != 0
    }

    /// How many cells are marked (voxels, for an edge of 1).
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// Marks every cell `other` marks too.
    pub fn union(&mut self, other: &ViewMask) {
        assert_eq!(
            (self.dims, self.edge),
            (other.dims, other.edge),
            "view masks of different volumes or cells"
        );
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
    }

    /// Per brick of `edge` voxels (x fastest over the bricks; a multiple of the mask's
    /// cells): whether it holds a marked cell.
    pub fn bricks(&self, edge: usize) -> Vec<bool> {
        assert!(
            edge.is_multiple_of(self.edge),
            "bricks of {edge} over cells of {}",
            self.edge
        );
        let (grid, cells) = (grid_of(self.dims, edge), self.grid());
        let mut out = vec![false; grid.iter().product()];
        let k = edge / self.edge;
        for (w, &word) in self.words.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let i = w * 32 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let c = crate::volume::voxel_of(i, cells).map(|c| c / k);
                out[c[0] + grid[0] * (c[1] + grid[1] * c[2])] = true;
            }
        }
        out
    }
}

/// Cells of `edge` voxels per axis of a volume of `dims`.
pub fn grid_of(dims: [usize; 3], edge: usize) -> [usize; 3] {
    dims.map(|n| n.div_ceil(edge.max(1)).max(1))
}

/// Words of a mask of a volume of `dims` in cells of `edge`.
pub fn words_for(dims: [usize; 3], edge: usize) -> usize {
    grid_of(dims, edge)
        .iter()
        .product::<usize>()
        .div_ceil(32)
        .max(1)
}

/// A [`ViewMask`] being marked by the CPU twin's ray cast (on rayon threads).
#[derive(Debug)]
pub struct ViewMarks {
    dims: [usize; 3],
    words: Vec<AtomicU32>,
    marking: Marking,
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
            marking: self.marking,
        }
    }
}

impl ViewMarks {
    pub fn new(dims: [usize; 3], marking: Marking) -> Self {
        ViewMarks {
            dims,
            words: (0..words_for(dims, marking.edge))
                .map(|_| AtomicU32::new(0))
                .collect(),
            marking,
        }
    }

    /// Marks the cells of the voxels an AO read at `ao_at` for the sample at `sample`
    /// weighs (the twin of `mark_ao` in `shaders/raycast.wgsl`).
    pub fn mark(&self, sample: Vec3, ao_at: Vec3) {
        let d = self.dims;
        let [x, y, z] = match self.marking.footprint {
            Footprint::Trilinear => trilinear_footprint(d, ao_at),
            Footprint::AtSample => trilinear_footprint(d, sample),
            Footprint::Nearest => {
                let c = ao_at * Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
                let n = [0, 1, 2].map(|a| (c[a].floor().max(0.0) as usize).min(d[a] - 1));
                [[n[0]; 2], [n[1]; 2], [n[2]; 2]]
            }
        };
        let e = self.marking.edge.max(1);
        let g = grid_of(d, e);
        for k in z[0] / e..=z[1] / e {
            for j in y[0] / e..=y[1] / e {
                for i in x[0] / e..=x[1] / e {
                    let c = i + g[0] * (j + g[1] * k);
                    self.words[c / 32].fetch_or(1 << (c % 32), Ordering::Relaxed);
                }
            }
        }
    }

    pub fn into_mask(self) -> ViewMask {
        ViewMask {
            dims: self.dims,
            edge: self.marking.edge.max(1),
            words: self.words.into_iter().map(AtomicU32::into_inner).collect(),
        }
    }
}
