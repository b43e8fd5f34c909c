//! How the viewport cuts an image into pieces that fit the pacer's slice: strips of rows,
//! and tiles of a band too costly for one slice, each costed by what the same part of
//! the picture took last time ([`TileCosts`]); see docs/ui-never-waits.md.

/// Tallest strip, in rows.
pub(super) const MAX_STRIP_ROWS: u32 = 64;

/// Lowest strip, in rows: the ray caster's workgroups are 8 rows high.
pub(super) const MIN_STRIP_ROWS: u32 = 8;

/// Narrowest tile, in columns: a band of [`MIN_STRIP_ROWS`] that does not fit in a slice
/// is cut into tiles of this many columns times a power of two.
pub(super) const MIN_TILE_COLUMNS: u32 = 16;

/// A tile of the image: first column, first row, columns, rows.
pub(super) type Tile = (u32, u32, u32, u32);

/// Cells across and down of [`TileCosts`].
const COST_GRID: usize = 32;

/// What a ray costs across the viewport, measured tile by tile: seconds per pixel times
/// the step (a ray's samples go as 1 / step), on a grid of [`COST_GRID`]² cells over
/// the image, whatever its size. On a picture that changes little from one image to the
/// next (a drag, or the switch to and from interactive quality), the next tile over the
/// same part costs about the same: rays through the volume cost many times those beside
/// it, which the pacer's mean rate for the label cannot tell, so strips cut by that rate
/// overran the slice, and the UI frame behind it, several times over. Each submission
/// also costs a fixed time (about 4 ms on lavapipe), the least of the recent tiles'.
#[derive(Debug)]
pub(super) struct TileCosts {
    cells: Vec<Option<f64>>,
    /// The last tiles' times (s), the least of which is the fixed cost.
    recent: std::collections::VecDeque<f64>,
}

/// Tiles whose least time is the fixed cost of one.
pub(super) const RECENT_TILES: usize = 32;

impl Default for TileCosts {
    fn default() -> Self {
        TileCosts {
            cells: vec![None; COST_GRID * COST_GRID],
            recent: Default::default(),
        }
    }
}

impl TileCosts {
    /// The cells a tile of an image of `size` overlaps, each with the overlap in pixels
    /// and as a fraction of the cell.
    fn overlaps(size: (u32, u32), (x0, y0, w, h): Tile) -> Vec<(usize, f64, f64)> {
        let g = COST_GRID as f64;
        let axis = |from: u32, len: u32, n: u32| {
            let n = n.max(1) as f64;
            let (a, b) = (from as f64, (from + len).min(n as u32) as f64);
            let cell = n / g;
            let first = (a / cell).floor() as usize;
            let last = ((b / cell).ceil() as usize).clamp(first + 1, COST_GRID);
            (first..last)
                .map(move |c| {
                    let (lo, hi) = (c as f64 * cell, (c + 1) as f64 * cell);
                    (c, (hi.min(b) - lo.max(a)).max(0.0), cell)
                })
                .filter(|o| o.1 > 0.0)
        };
        let mut out = Vec::new();
        for (cy, py, ch) in axis(y0, h, size.1) {
            for (cx, px, cw) in axis(x0, w, size.0) {
                out.push((cy * COST_GRID + cx, px * py, (px * py) / (cw * ch)));
            }
        }
        out
    }

    /// A tile of an image of `size` at `step` (voxels) took `took` seconds: the cells
    /// it covers move halfway towards its cost per pixel, in proportion to how much of
    /// each it covers (one timing is noisy).
    pub(super) fn record(&mut self, size: (u32, u32), step: f32, tile: Tile, took: f64) {
        let overlaps = Self::overlaps(size, tile);
        let pixels: f64 = overlaps.iter().map(|o| o.1).sum();
        if pixels <= 0.0 {
            return;
        }
        if self.recent.len() == RECENT_TILES {
            self.recent.pop_front();
        }
        self.recent.push_back(took);
        let measured = (took - self.fixed()).max(0.0) * step as f64 / pixels;
        for (i, _, fraction) in overlaps {
            let c = &mut self.cells[i];
            *c = Some(c.map_or(measured, |old| {
                old + 0.5 * fraction.min(1.0) * (measured - old)
            }));
        }
    }

    /// What a tile of an image of `size` at `step` will cost, if every cell it covers
    /// was measured.
    pub(super) fn estimate(&self, size: (u32, u32), step: f32, tile: Tile) -> Option<f64> {
        let secs: Option<f64> = Self::overlaps(size, tile)
            .into_iter()
            .map(|(i, pixels, _)| self.cells[i].map(|c| c * pixels))
            .sum();
        secs.map(|s| self.fixed() + s / step.max(1e-3) as f64)
    }

    /// The fixed cost of a tile (s).
    fn fixed(&self) -> f64 {
        self.recent.iter().copied().reduce(f64::min).unwrap_or(0.0)
    }

    /// Forgets everything (a new volume).
    pub(super) fn clear(&mut self) {
        self.cells.fill(None);
        self.recent.clear();
    }
}

/// The next piece of an image `width` wide from `(x0, y0)`, given the whole slice and
/// what is left of it (seconds), whether nothing is queued (`idle`: then a piece that
/// does not fit goes alone, so the image always moves on) and a tile's cost; `None`:
/// wait for the next frame. Whole strips, tallest first, where a band of
/// [`MIN_STRIP_ROWS`] fits in a slice; else tiles of that band, widest first.
pub(super) fn next_tile(
    (width, (x0, y0)): (u32, (u32, u32)),
    (slice, left): (f64, f64),
    idle: bool,
    estimate: impl Fn(Tile) -> f64,
) -> Option<Tile> {
    let band = (0, y0, width, MIN_STRIP_ROWS);
    if x0 == 0 && estimate(band) <= slice {
        // The next frame's slice takes what does not fit in this one's.
        let tallest = std::iter::successors(Some(MAX_STRIP_ROWS), |r| {
            (*r > MIN_STRIP_ROWS).then_some(r / 2)
        })
        .map(|rows| (0, y0, width, rows))
        .find(|&t| estimate(t) <= left);
        return tallest.or(idle.then_some(band));
    }
    // A band that overruns a slice on its own.
    let widest = std::iter::successors(Some(width - x0), |c| {
        (*c > MIN_TILE_COLUMNS).then_some((c / 2).next_multiple_of(MIN_TILE_COLUMNS))
    })
    .map(|columns| (x0, y0, columns, MIN_STRIP_ROWS))
    .find(|&t| estimate(t) <= left);
    let smallest = (x0, y0, MIN_TILE_COLUMNS.min(width - x0), MIN_STRIP_ROWS);
    widest.or(idle.then_some(smallest))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: f64 = 1e-3;

    fn close(a: Option<f64>, b: f64) -> bool {
        a.is_some_and(|a| (a - b).abs() < 1e-9)
    }

    #[test]
    fn a_tile_is_costed_by_what_its_part_of_the_picture_took() {
        let mut c = TileCosts::default();
        let size = (128, 128);
        assert_eq!(
            c.estimate(size, 1.0, (0, 0, 128, 8)),
            None,
            "nothing measured"
        );
        // The fixed cost of a submission: a tile over nothing costs 4 ms.
        c.record(size, 1.0, (0, 0, 128, 8), 4.0 * MS);
        assert!(close(c.estimate(size, 1.0, (0, 0, 128, 8)), 4.0 * MS));
        assert!(close(c.estimate(size, 1.0, (0, 0, 16, 8)), 4.0 * MS));
        // A band through the volume: 24 ms, 20 of it rays.
        c.record(size, 1.0, (0, 64, 128, 8), 24.0 * MS);
        assert!(close(c.estimate(size, 1.0, (0, 64, 128, 8)), 24.0 * MS));
        // Half of it is half its rays, plus the fixed cost.
        assert!(close(c.estimate(size, 1.0, (0, 64, 64, 8)), 14.0 * MS));
        // The rows beside it were measured empty, the rows below not at all.
        assert!(close(c.estimate(size, 1.0, (0, 0, 128, 8)), 4.0 * MS));
        assert_eq!(c.estimate(size, 1.0, (0, 72, 128, 8)), None);
        // At twice the step the rays take half as long.
        assert!(close(c.estimate(size, 2.0, (0, 64, 128, 8)), 14.0 * MS));
    }

    #[test]
    fn tile_costs_carry_over_to_another_image_size() {
        let mut c = TileCosts::default();
        // The full-quality image's bottom half (512 × 256 pixels at step 0.5) took 260
        // ms, 4 of them fixed.
        c.record((512, 512), 0.5, (0, 0, 512, 256), 4.0 * MS);
        c.record((512, 512), 0.5, (0, 256, 512, 256), 260.0 * MS);
        // A quarter of the size on each axis at twice the step: 1/16 of the rays, each
        // half as long.
        let e = c.estimate((128, 128), 1.0, (0, 64, 128, 64));
        assert!(close(e, 4.0 * MS + 256.0 * MS / 32.0), "{e:?}");
    }

    #[test]
    fn a_new_timing_moves_a_tile_cost_halfway() {
        let mut c = TileCosts::default();
        let size = (64, 64);
        c.record(size, 1.0, (0, 0, 64, 8), 2.0 * MS);
        c.record(size, 1.0, (0, 8, 64, 8), 12.0 * MS);
        c.record(size, 1.0, (0, 8, 64, 8), 22.0 * MS);
        // Rays: 10 ms, then 20: the cost is 15 + 2.
        assert!(close(c.estimate(size, 1.0, (0, 8, 64, 8)), 17.0 * MS));
    }

    #[test]
    fn strips_fit_what_is_left_and_costly_bands_go_in_tiles() {
        // 1 ms per row of 128 pixels, 4 ms per 16 columns of a band through the volume.
        let cheap = |t: Tile| t.3 as f64 * 1e-3 * t.2 as f64 / 128.0;
        // A 25 ms slice with 20 ms left: 16 rows (32 would not fit).
        assert_eq!(
            next_tile((128, (0, 0)), (0.025, 0.020), true, cheap),
            Some((0, 0, 128, 16))
        );
        // Nothing fits and something is queued: wait; nothing queued: the lowest strip.
        assert_eq!(next_tile((128, (0, 8)), (0.025, 0.001), false, cheap), None);
        assert_eq!(
            next_tile((128, (0, 8)), (0.025, 0.001), true, cheap),
            Some((0, 8, 128, 8))
        );
        // A band of 8 rows costs 32 ms, more than a slice: tiles of it, widest that fits.
        let costly = |t: Tile| t.2 as f64 / 16.0 * 4e-3;
        assert_eq!(
            next_tile((128, (0, 8)), (0.025, 0.020), true, costly),
            Some((0, 8, 64, 8))
        );
        assert_eq!(
            next_tile((128, (64, 8)), (0.025, 0.010), false, costly),
            Some((64, 8, 32, 8))
        );
        assert_eq!(
            next_tile((128, (96, 8)), (0.025, 0.0), true, costly),
            Some((96, 8, 16, 8))
        );
    }
}
