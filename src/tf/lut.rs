//! The transfer function baked for the GPU, its CPU twin of the shader's filtered fetch
//! and the empty-space test, and the opacity correction for a step length.

/// Entries in a baked [`Lut`] (≥ 1024 required).
///
/// 4096 is the 12-bit range CT scanners store (−1024…3071 HU), so a LUT over a typical
/// CT volume has exactly one entry per HU and every integer-HU control point lands on an
/// entry. As `Rgba32Float` it is 64 KiB, inside wgpu's default `max_texture_dimension_1d`
/// (8192).
pub const LUT_ENTRIES: usize = 4096;

/// A transfer function baked for the GPU: entry `i` holds the function at
/// `min + (max − min) · i / (len − 1)`, as straight (not premultiplied) RGBA.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut {
    pub min: f64,
    pub max: f64,
    pub rgba: Vec<[f32; 4]>,
    /// The function's own window in data units (first to last point value): black to
    /// white of the intensity projections (MIP, MinIP, average).
    pub window: [f64; 2],
    /// The isosurface mode's default value: where the opacity first reaches half its
    /// maximum (a bone preset's bone, say).
    pub iso: f64,
}

/// Data value of entry `i` of a `len`-entry table over `[min, max]`. Multiplying
/// before dividing keeps integer-spaced tables (one HU per entry) exact.
pub(super) fn entry_value(min: f64, max: f64, len: usize, i: usize) -> f64 {
    if len < 2 {
        return min;
    }
    min + (max - min) * i as f64 / (len - 1) as f64
}

impl Lut {
    /// Data value that entry `i` holds: `min + (max − min) · i / (len − 1)`.
    pub fn entry_value(&self, i: usize) -> f64 {
        entry_value(self.min, self.max, self.rgba.len(), i)
    }

    /// Continuous entry coordinate `t = (value − min) · (len − 1) / (max − min)`,
    /// clamped to `[0, len − 1]`. Needs `len ≥ 2` and a non-NaN value.
    fn coord(&self, value: f64) -> f64 {
        let last = (self.rgba.len() - 1) as f64;
        let span = self.max - self.min;
        let t = if span > 0.0 {
            (value - self.min) * last / span
        } else {
            0.0
        };
        t.clamp(0.0, last)
    }

    /// Linear interpolation between entries, as a GPU's linear filter on a 1-D texture
    /// with clamp-to-edge does.
    ///
    /// The mapping, which the shader must use too:
    /// `t = clamp((value − min) · (len − 1) / (max − min), 0, len − 1)`,
    /// `i = min(floor(t), len − 2)`, `f = t − i`,
    /// result `= rgba[i] · (1 − f) + rgba[i + 1] · f`.
    /// With hardware filtering this is texture coordinate `u = (t + 0.5) / len` (texel
    /// `i` sits at `u = (i + 0.5) / len`), up to the filter's weight precision; an
    /// `Rgba32Float` table is not filterable without `FLOAT32_FILTERABLE`, so there the
    /// shader does this lerp itself with two `textureLoad`s. NaN gives 0.
    pub fn sample(&self, value: f64) -> [f32; 4] {
        match self.rgba.len() {
            _ if value.is_nan() => [0.0; 4],
            0 => [0.0; 4],
            1 => self.rgba[0],
            len => {
                let t = self.coord(value);
                let i = (t.floor() as usize).min(len - 2);
                let f = (t - i as f64) as f32;
                let (a, b) = (self.rgba[i], self.rgba[i + 1]);
                std::array::from_fn(|c| a[c] * (1.0 - f) + b[c] * f)
            }
        }
    }

    /// True if every entry that [`Lut::sample`] can touch for a value in `[lo, hi]`
    /// (data units, either order) has alpha exactly 0 — the conservative test for
    /// empty-space skipping.
    ///
    /// It covers entries `floor(t(lo)) − 1 ..= floor(t(hi)) + 2` (clamped): the two
    /// neighbours linear interpolation reads plus one more on each side for the
    /// shader's f32 rounding of `t`. It speaks for the table, i.e. what is rendered: a
    /// function feature narrower than one entry is lost when baking, not here. NaN
    /// bounds answer false.
    pub fn is_transparent_over(&self, lo: f64, hi: f64) -> bool {
        if lo.is_nan() || hi.is_nan() {
            return false;
        }
        let len = self.rgba.len();
        if len < 2 {
            return self.rgba.iter().all(|e| e[3] == 0.0);
        }
        let (lo, hi) = (lo.min(hi), lo.max(hi));
        let first = (self.coord(lo).floor() as usize).saturating_sub(1);
        let last = (self.coord(hi).floor() as usize + 2).min(len - 1);
        self.rgba[first..=last].iter().all(|e| e[3] == 0.0)
    }
}

/// Opacity correction for a step of `step` voxels when opacities are defined per one
/// voxel: α' = 1 − (1 − α)^step — the standard correction (Engel et al., *Real-Time
/// Volume Graphics*, 2006; Eq. 6, Appendix A.1 of Imagire et al., with step = Δd/Δd₀).
///
/// Computed as `−expm1(step · ln_1p(−α))` in f64 so small opacities keep their digits
/// and `step == 1` returns `alpha` unchanged; the shader's `1 − pow(1 − α, step)` in
/// f32 agrees to f32 rounding. `alpha` is clamped to [0, 1] (NaN → 0); a step ≤ 0
/// (or NaN) gives 0, an infinite step 1 for any α > 0.
pub fn correct_opacity(alpha: f32, step: f32) -> f32 {
    let alpha = if alpha.is_nan() {
        0.0
    } else {
        alpha.clamp(0.0, 1.0)
    };
    if step.is_nan() || step <= 0.0 || alpha == 0.0 {
        return 0.0;
    }
    if alpha == 1.0 {
        return 1.0;
    }
    let a = f64::from(alpha);
    (-(f64::from(step) * (-a).ln_1p()).exp_m1()) as f32
}
