//! Series assembly: images grouped by SeriesInstanceUID, size and orientation, the
//! choice among several series, and the geometry from ImagePositionPatient.

use super::header::*;
use crate::volume::orient::{AffineSource, Orientation};
use crate::volume::{VolumeError, display_path, escape_controls, fmt_bytes, fmt_dims, short_name};
use glam::{DMat3, DVec3};
use std::collections::BTreeSet;
use std::path::Path;

/// Groups scanned files into series candidates, most slices first. Multi-frame files
/// are each their own candidate; duplicate SOPInstanceUIDs are dropped with a warning.
pub fn group_series(files: &[FileInfo], warnings: &mut Vec<String>) -> Vec<Series> {
    let mut groups: Vec<(String, Vec<Slice>, usize)> = Vec::new();
    let mut seen_sop = std::collections::HashSet::new();
    for (k, f) in files.iter().enumerate() {
        if !f.sop_uid.is_empty() && !seen_sop.insert((f.series_uid.clone(), f.sop_uid.clone())) {
            warnings.push(format!(
                "{} repeats SOPInstanceUID {} of another file; skipping it",
                display_path(&f.path),
                short_name(&f.sop_uid)
            ));
            continue;
        }
        for s in &f.slices {
            let mut s = s.clone();
            s.file = k;
            // Stack key: size and orientation to 1e-3; a multi-frame file stands alone.
            let o = s
                .orientation
                .map(|[r, c]| [r, c].map(|d| d.to_array().map(|x| (x * 1000.0).round() as i64)))
                .unwrap_or_default();
            let key = format!(
                "{}|{}x{}|{:?}|{}|{}|{}",
                f.series_uid,
                s.rows,
                s.cols,
                o,
                f.bits_allocated,
                f.samples_per_pixel,
                if f.frames > 1 { k as i64 } else { -1 }
            );
            match groups.iter_mut().find(|g| g.0 == key) {
                Some(g) => g.1.push(s),
                None => groups.push((key, vec![s], k)),
            }
        }
    }
    let mut per_uid: std::collections::HashMap<String, usize> = Default::default();
    let mut out: Vec<Series> = groups
        .into_iter()
        .map(|(_, slices, k)| {
            let f = &files[k];
            let n = per_uid.entry(f.series_uid.clone()).or_default();
            *n += 1;
            let id = if *n == 1 {
                f.series_uid.clone()
            } else {
                format!("{}#{}", f.series_uid, n)
            };
            Series {
                id,
                description: f.series_description.clone(),
                modality: f.modality.clone(),
                slices,
            }
        })
        .collect();
    out.sort_by_key(|s| std::cmp::Reverse(s.slices.len()));
    out
}

/// The stack geometry of a series: slices in order and the voxel → world (RAS) map.
#[derive(Debug, Clone)]
pub struct Geometry {
    pub order: Vec<usize>,
    pub spacing: [f32; 3],
    pub orientation: Orientation,
}

/// Orders the slices and derives spacing and affine from their positions, reporting
/// gaps, duplicates and missing slices. `thickness` is used for a lone slice only.
pub fn geometry(
    slices: &[Slice],
    thickness: Option<f64>,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Geometry, VolumeError> {
    let n = slices.len();
    let first = &slices[0];
    let px = first.pixel_spacing.unwrap_or_else(|| {
        warnings.push("no PixelSpacing: using 1 mm in-plane".into());
        [1.0, 1.0]
    });
    let positioned = slices.iter().all(|s| s.position.is_some());
    let Some([row, col]) = first.orientation.filter(|_| positioned) else {
        // No usable geometry: stack in file/instance order, 1 mm apart.
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&i| (slices[i].instance_number, slices[i].file, slices[i].frame));
        if n > 1 {
            warnings.push(
                "no ImagePositionPatient/ImageOrientationPatient for every slice: slices stacked in instance order, 1 mm apart, orientation assumed"
                    .into(),
            );
        }
        let spacing = [
            px[1] as f32,
            px[0] as f32,
            thickness.filter(|_| n == 1).unwrap_or(1.0) as f32,
        ];
        let mut spacing = spacing;
        let mut o = Orientation::from_spacing(spacing);
        crate::volume::fix_spacing(
            &mut spacing,
            &mut o,
            &["PixelSpacing[1]", "PixelSpacing[0]", "SliceThickness"],
            warnings,
        );
        return Ok(Geometry {
            order,
            spacing,
            orientation: Orientation::from_spacing(spacing),
        });
    };
    let normal = row.cross(col);
    let dist = |s: &Slice| s.position.unwrap_or(DVec3::ZERO).dot(normal);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        dist(&slices[a])
            .total_cmp(&dist(&slices[b]))
            .then(slices[a].instance_number.cmp(&slices[b].instance_number))
    });
    // Duplicate positions: keep the first of each (by instance order), say so.
    let mut kept: Vec<usize> = Vec::with_capacity(n);
    let mut dups = 0;
    for &i in &order {
        if let Some(&last) = kept.last()
            && (dist(&slices[i]) - dist(&slices[last])).abs() < 1e-3
        {
            dups += 1;
            continue;
        }
        kept.push(i);
    }
    if dups > 0 {
        warnings.push(format!(
            "{dups} slice{} repeat the position of another slice (several echoes or time points?); keeping one per position, {} slices",
            if dups == 1 { "" } else { "s" },
            kept.len()
        ));
    }
    let order = kept;
    let m = order.len();
    let p0 = slices[order[0]].position.unwrap_or(DVec3::ZERO);
    let (step, dz) = if m > 1 {
        let gaps: Vec<f64> = order
            .windows(2)
            .map(|w| dist(&slices[w[1]]) - dist(&slices[w[0]]))
            .collect();
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        // Positions are decimal strings, often rounded to 0.1 mm: gaps jitter by that
        // much in perfectly regular series, so only larger differences are reported.
        let tol = (0.01 * median).max(0.15);
        let irregular = gaps.iter().filter(|g| (*g - median).abs() > tol).count();
        if irregular > 0 {
            let missing: f64 = gaps
                .iter()
                .map(|g| (g / median).round() - 1.0)
                .filter(|k| *k >= 1.0)
                .sum();
            let (lo, hi) = (sorted[0], sorted[sorted.len() - 1]);
            let mut msg = format!(
                "slice positions are irregular: {irregular} of {} gaps differ from the median {median:.4} mm by more than {tol:.2} mm (range {lo:.4} … {hi:.4} mm); the volume spaces all slices {median:.4} mm apart",
                gaps.len()
            );
            if missing >= 1.0 {
                msg.push_str(&format!("; about {missing} slice(s) seem to be missing"));
            }
            warnings.push(msg);
        }
        // The spacing is the distance between the first two slices, as dcm2niix takes
        // it, unless that gap is an irregular one; the slice axis is the normal.
        let p1 = slices[order[1]].position.unwrap_or(DVec3::ZERO);
        let first = p1 - p0;
        let dz = if (gaps[0] - median).abs() <= tol {
            first.length()
        } else {
            median
        };
        let cos = first.normalize_or_zero().dot(normal);
        if cos < (1.0f64).to_radians().cos() {
            warnings.push(format!(
                "slices are offset {:.1}° from their normal (gantry tilt?); the volume is drawn unsheared",
                cos.clamp(-1.0, 1.0).acos().to_degrees()
            ));
        }
        (normal * dz, dz)
    } else {
        let t = thickness.unwrap_or(1.0);
        (normal * t, t)
    };
    let mut spacing = [px[1] as f32, px[0] as f32, dz.abs() as f32];
    let lps_to_ras = DVec3::new(-1.0, -1.0, 1.0);
    let mut orientation = Orientation {
        linear: DMat3::from_cols(
            row * px[1] * lps_to_ras,
            col * px[0] * lps_to_ras,
            step * lps_to_ras,
        ),
        offset: p0 * lps_to_ras,
        source: AffineSource::Header,
    };
    crate::volume::fix_spacing(
        &mut spacing,
        &mut orientation,
        &[
            "PixelSpacing[1] (column spacing)",
            "PixelSpacing[0] (row spacing)",
            "slice spacing from ImagePositionPatient",
        ],
        warnings,
    );
    if !orientation.is_valid() {
        return Err(VolumeError::invalid(
            path,
            "ImageOrientationPatient and ImagePositionPatient give a degenerate affine",
        ));
    }
    Ok(Geometry {
        order: order.to_vec(),
        spacing,
        orientation,
    })
}

/// Which series to load (its index in `series`): `None` = the one with most slices.
pub(super) fn choose(
    series: &[Series],
    want: Option<&str>,
    path: &Path,
) -> Result<usize, VolumeError> {
    let Some(want) = want else {
        return (!series.is_empty())
            .then_some(0)
            .ok_or_else(|| VolumeError::invalid(path, "no DICOM images found"));
    };
    if let Ok(k) = want.parse::<usize>() {
        return (k < series.len()).then_some(k).ok_or_else(|| {
            VolumeError::invalid(
                path,
                format!(
                    "--series {k}: there are {} series here (numbered from 0: 0 … {})",
                    series.len(),
                    series.len().saturating_sub(1)
                ),
            )
        });
    }
    series.iter().position(|s| s.id == want).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "--series {}: no such SeriesInstanceUID here (`volao info` lists them)",
                short_name(want)
            ),
        )
    })
}

/// One line per series candidate, for `volao info` and warnings (the file's text with
/// control characters escaped, so a damaged UID or description cannot break a line).
pub fn describe_series(series: &[Series], chosen: &str) -> String {
    series
        .iter()
        .enumerate()
        .map(|(k, s)| {
            format!(
                "[{k}]{} {} — {} {}×{} slice{}{}",
                if s.id == chosen { "*" } else { "" },
                escape_controls(&s.id),
                s.slices.len(),
                s.slices[0].cols,
                s.slices[0].rows,
                if s.slices.len() == 1 { "" } else { "s" },
                if s.description.is_empty() && s.modality.is_empty() {
                    String::new()
                } else {
                    escape_controls(&format!(", {} {}", s.modality, s.description))
                }
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What series assembly decides from the headers alone, before any pixel is decoded.
#[derive(Debug, Clone)]
pub struct Assembly {
    /// Every series candidate, most slices first.
    pub series: Vec<Series>,
    /// The one to load: an index into `series`.
    pub chosen: usize,
    /// The scanned files (indices) whose images form it.
    pub files_used: BTreeSet<usize>,
    /// Its slices in stack order, spacing and affine.
    pub geometry: Geometry,
    /// Voxels along x (columns), y (rows) and z (slices kept).
    pub dims: [usize; 3],
    /// Bytes of stored voxels: `dims` times the bytes of one sample.
    pub bytes: u64,
}

/// Series assembly on scanned headers (no pixels): groups the images, chooses the
/// series, refuses what cannot be decoded or does not fit in `max_bytes`, and derives
/// the geometry. `path` is what the user gave, for messages.
pub fn plan(
    infos: &[FileInfo],
    series_wanted: Option<&str>,
    path: &Path,
    max_bytes: u64,
    warnings: &mut Vec<String>,
) -> Result<Assembly, VolumeError> {
    let series = group_series(infos, warnings);
    let k = choose(&series, series_wanted, path)?;
    let chosen = &series[k];
    let files_used: BTreeSet<usize> = chosen.slices.iter().map(|s| s.file).collect();
    let first = &infos[chosen.slices[0].file];
    if series.len() > 1 {
        warnings.push(format!(
            "{} series here; loading [{}] {} (choose another with --series N or UID; `volao info` lists them)",
            series.len(),
            series.iter().position(|s| s.id == chosen.id).unwrap_or(0),
            escape_controls(&chosen.id)
        ));
    }
    if first.samples_per_pixel != 1 {
        return Err(VolumeError::unsupported(
            &first.path,
            format!(
                "{} samples per pixel ({}): volao renders scalar (greyscale) volumes only",
                first.samples_per_pixel, first.photometric
            ),
        ));
    }
    for &f in &files_used {
        let (name, ok) = transfer_syntax(&infos[f].transfer_syntax);
        if !ok {
            return Err(VolumeError::unsupported(
                &infos[f].path,
                format!(
                    "transfer syntax {name} cannot be decoded by this build (dicom-rs without system libraries; JPEG-LS needs CharLS) — convert it with e.g. `gdcmconv --raw` or dcm2niix"
                ),
            ));
        }
    }
    let geometry = geometry(&chosen.slices, first.slice_thickness, path, warnings)?;
    let (rows, cols) = (chosen.slices[0].rows, chosen.slices[0].cols);
    let dims = [cols as usize, rows as usize, geometry.order.len()];
    let bytes_per = u64::from(first.bits_allocated / 8);
    let bytes = (u64::from(rows) * u64::from(cols))
        .checked_mul(dims[2] as u64)
        .and_then(|v| v.checked_mul(bytes_per))
        .unwrap_or(u64::MAX);
    if bytes > max_bytes {
        return Err(VolumeError::TooLarge {
            path: path.to_owned(),
            dims: fmt_dims(dims),
            ty: format!("{}-bit", first.bits_allocated),
            bytes: fmt_bytes(bytes),
            limit: fmt_bytes(max_bytes),
        });
    }
    Ok(Assembly {
        series,
        chosen: k,
        files_used,
        geometry,
        dims,
        bytes,
    })
}
