//! `volao bench render FILE --labels SEG`: what a segmentation costs — frames with it
//! (timed beside those without, in `render`) and, here, `V_PAO`'s update after hiding a
//! segment against its recomputation.

use anyhow::Result;
use std::path::Path;
use volao::ao::AoSettings;
use volao::ao::cao::{CaoGpu, CaoSetup, CaoVolume};
use volao::ao::lao::Rays;
use volao::ao::sparse::{Coverage, bricks_holding, grid_of};
use volao::gpu::Gpu;
use volao::labels::LabelMap;
use volao::labels::style::{self, Classes, SegmentStyle, Styles};
use volao::render::gpu::RenderVolume;
use volao::texels::segments::SegmentTexels;
use volao::tf::TransferFunction;
use volao::volume::Volume;

/// A segmentation loaded onto a volume with its styles and looks.
pub struct Segmentation {
    pub labels: LabelMap,
    pub classes: Classes,
    pub styles: Styles,
    pub texels: SegmentTexels,
}

impl Segmentation {
    /// `seg` (with `table`) on `volume`'s grid, styled by `specs` (`--segment`).
    pub fn load(
        seg: &Path,
        table: Option<&Path>,
        specs: &[String],
        volume: &Volume,
    ) -> Result<Self> {
        let labels = volao::labels::load(seg, table, volume)?.labels;
        let mut styles = Styles::default();
        for spec in specs {
            styles.apply(&labels, spec).map_err(anyhow::Error::msg)?;
        }
        let classes = Classes::of(&labels).map_err(anyhow::Error::msg)?;
        let texels = style::segment_texels(&labels, &classes, &styles, &[]);
        Ok(Segmentation {
            labels,
            classes,
            styles,
            texels,
        })
    }

    /// The looks with the segments `pattern` names hidden.
    fn hiding(&self, pattern: &str) -> SegmentTexels {
        let mut styles = self.styles.clone();
        for key in self.labels.find(pattern) {
            let style = SegmentStyle {
                visible: false,
                ..styles.get(key)
            };
            styles.set(key, style);
        }
        style::segment_texels(&self.labels, &self.classes, &styles, &[])
    }
}

/// What `--json` prints of the update.
#[derive(serde::Serialize)]
struct Updated {
    hidden: String,
    changed_bricks: usize,
    bricks: usize,
    lao_bricks: usize,
    recomputed_voxels: u64,
    update_ms: f64,
    recompute_ms: f64,
    same_bits: bool,
}

/// Times `V_PAO`'s update after hiding `hide` (default: the segment covering the most
/// bricks below a tenth of them) on `vol` (with the segmentation set) against computing
/// it anew with the segment hidden, and checks the two hold the same bits.
pub fn pao_update(
    gpu: &Gpu,
    vol: &RenderVolume,
    tf: &TransferFunction,
    s: &Segmentation,
    hide: Option<&str>,
    json: bool,
) -> Result<()> {
    let ao = AoSettings::default();
    let rays = Rays::uniform(ao.rays.directions());
    let setup = CaoSetup {
        tf,
        rays: &rays,
        samples: ao.samples,
        msaa: ao.msaa,
    };
    let texels = &vol.segment_texels;
    let Some(current) = texels.as_ref() else {
        anyhow::bail!("bench render --labels: the volume holds no segmentation");
    };
    // The bricks a change touches (what "a tenth of the bricks" counts).
    let bricks_of = |voxels: &[bool]| bricks_holding(voxels, current.dims);
    let changed_by =
        |pattern: &str| bricks_of(&current.voxels_changed_by(&s.hiding(pattern).table));
    let count = |m: &[bool]| m.iter().filter(|&&c| c).count();
    let hide = match hide {
        Some(p) => p.to_owned(),
        None => {
            let bricks: usize = grid_of(current.dims).iter().product();
            s.labels
                .segments
                .iter()
                .filter(|seg| seg.voxels > 0)
                .map(|seg| (count(&changed_by(&seg.key.value.to_string())), seg))
                .filter(|&(n, _)| n * 10 < bricks)
                .max_by_key(|&(n, _)| n)
                .map(|(_, seg)| seg.key.value.to_string())
                .ok_or_else(|| {
                    anyhow::anyhow!("no segment covers fewer than a tenth of the bricks")
                })?
        }
    };
    let names: Vec<String> = s
        .labels
        .find(&hide)
        .iter()
        .filter_map(|k| {
            s.labels
                .index_of(*k)
                .map(|i| s.labels.segments[i].name.clone())
        })
        .collect();
    let hidden = s.hiding(&hide);
    let changed_voxels = current.voxels_changed_by(&hidden.table);
    let changed = bricks_of(&changed_voxels);
    let make = |v: &RenderVolume| -> Result<CaoGpu> {
        let bricks = Coverage::Readable.bricks(&v.texels, v.ranges(), tf);
        Ok(CaoGpu::new(gpu, v, setup, bricks, &|_, _| {})?)
    };
    // Shown, then hidden and updated.
    let mut shown_vol = RenderVolume::from_texels(gpu, vol.texels.clone(), tf, 1.0)?;
    shown_vol.set_segments(gpu, Some(current.clone()));
    let mut cao = make(&shown_vol)?;
    shown_vol.set_segments(gpu, Some(hidden.clone()));
    let update = cao.update_pao(gpu, &shown_vol.texels, &changed_voxels)?;
    // Computed anew with it hidden.
    let mut fresh_vol = RenderVolume::from_texels(gpu, vol.texels.clone(), tf, 1.0)?;
    fresh_vol.set_segments(gpu, Some(hidden));
    let fresh = make(&fresh_vol)?;
    let (a, b) = (
        cao.read(gpu, CaoVolume::Precomputed)?,
        fresh.read(gpu, CaoVolume::Precomputed)?,
    );
    let same_bits = a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits());
    let u = Updated {
        hidden: names.join(", "),
        changed_bricks: count(&changed),
        bricks: changed.len(),
        lao_bricks: update.lao_bricks,
        recomputed_voxels: update.recomputed,
        update_ms: update.seconds * 1e3,
        recompute_ms: fresh.precompute_seconds * 1e3,
        same_bits,
    };
    if json {
        println!("{}", serde_json::to_string(&u)?);
    } else {
        println!();
        println!(
            "V_PAO ({} rays × {} samples) after hiding {} ({} of {} bricks changed, {:.1} %): update {:.0} ms ({} voxels of {} bricks ray cast) vs recomputation {:.0} ms: {:.1}× faster; same bits: {}",
            rays.directions.len(),
            ao.samples,
            u.hidden,
            u.changed_bricks,
            u.bricks,
            100.0 * u.changed_bricks as f64 / u.bricks as f64,
            u.update_ms,
            u.recomputed_voxels,
            u.lao_bricks,
            u.recompute_ms,
            u.recompute_ms / u.update_ms.max(1e-9),
            if same_bits { "yes" } else { "NO" }
        );
    }
    Ok(())
}
