//! DICOM: a folder (or any one file) of a series, and single/multi-frame files.
//!
//! Reading is done by dicom-rs (`dicom-object`, `dicom-pixeldata`); this module turns
//! files into one volume:
//!
//! 1. **Scan**: every file's header up to the pixel data (a folder: all its files; one
//!    single-frame file: the files beside it with the same SeriesInstanceUID).
//! 2. **Group** the images by SeriesInstanceUID, then by size and orientation. The group
//!    with the most slices wins unless `--series` names another; the rest are listed.
//! 3. **Geometry** from ImagePositionPatient projected on the slice normal (row × column
//!    of ImageOrientationPatient) — never SliceThickness or SpacingBetweenSlices, which
//!    scanners fill inconsistently. Gaps, duplicates and missing slices are reported.
//! 4. **Voxels**: decoded, BitsStored-masked (sign-extended when signed), stacked in
//!    position order; RescaleSlope/Intercept become the volume's [`Scaling`] (HU stay HU),
//!    or are applied into f32 when slices disagree.
//!
//! World space is NIfTI's RAS+: DICOM's patient LPS with x and y negated.

use super::orient::{AffineSource, Orientation};
use super::{
    Scaling, Volume, VolumeError, VoxelData, display_path, fmt_bytes, fmt_dims, short_name,
};
use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions, Tag};
use dicom_pixeldata::PixelDecoder;
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// One 2-D image: a single-frame file, or one frame of a multi-frame file.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    pub file: usize,
    pub frame: u32,
    pub rows: u32,
    pub cols: u32,
    pub position: Option<DVec3>,
    /// Row direction (along a row, index i) and column direction (index j), LPS.
    pub orientation: Option<[DVec3; 2]>,
    /// (between rows, between columns) in mm, as PixelSpacing stores it.
    pub pixel_spacing: Option<[f64; 2]>,
    pub rescale: Scaling,
    pub instance_number: Option<i64>,
}

/// What a file's header says before its pixel data.
#[derive(Debug, Clone, PartialEq)]
pub struct FileInfo {
    pub path: PathBuf,
    pub series_uid: String,
    pub sop_uid: String,
    pub series_description: String,
    pub modality: String,
    pub transfer_syntax: String,
    pub frames: u32,
    pub bits_allocated: u16,
    pub bits_stored: u16,
    pub signed: bool,
    pub samples_per_pixel: u16,
    pub photometric: String,
    pub slice_thickness: Option<f64>,
    pub slices: Vec<Slice>,
}

/// One series candidate: the slices that form a volume.
#[derive(Debug, Clone)]
pub struct Series {
    /// SeriesInstanceUID, with `#2`, `#3`, … when one UID splits into several stacks.
    pub id: String,
    pub description: String,
    pub modality: String,
    pub slices: Vec<Slice>,
}

/// Whether `head` (a file's first bytes) carries the DICOM preamble magic.
pub fn has_dicm_magic(head: &[u8]) -> bool {
    head.get(128..132) == Some(b"DICM")
}

fn get_str(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let s = obj.get(tag)?.to_str().ok()?;
    let s = s.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    (!s.is_empty()).then(|| s.to_owned())
}

fn get_f64s(obj: &InMemDicomObject, tag: Tag) -> Option<Vec<f64>> {
    let v = obj.get(tag)?.to_multi_float64().ok()?;
    v.iter().all(|x| x.is_finite()).then_some(v)
}

fn get_int(obj: &InMemDicomObject, tag: Tag) -> Option<i64> {
    obj.get(tag)?.to_int::<i64>().ok()
}

/// The first item of sequence `seq` in `obj`.
fn item(obj: &InMemDicomObject, seq: Tag) -> Option<&InMemDicomObject> {
    obj.get(seq)?.items()?.first()
}

/// A functional group macro for `frame`: per-frame first, then shared.
fn group(obj: &InMemDicomObject, frame: u32, seq: Tag) -> Option<&InMemDicomObject> {
    obj.get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .and_then(|items| items.get(frame as usize))
        .and_then(|f| item(f, seq))
        .or_else(|| item(obj, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE).and_then(|s| item(s, seq)))
}

fn vec3(v: &[f64]) -> DVec3 {
    DVec3::new(v[0], v[1], v[2])
}

fn parse_orientation(v: Option<Vec<f64>>) -> Option<[DVec3; 2]> {
    let v = v.filter(|v| v.len() == 6)?;
    let (r, c) = (vec3(&v[..3]), vec3(&v[3..]));
    let ok = |d: DVec3| (d.length() - 1.0).abs() < 1e-2;
    (ok(r) && ok(c) && r.dot(c).abs() < 1e-2).then(|| [r.normalize(), c.normalize()])
}

fn parse_position(v: Option<Vec<f64>>) -> Option<DVec3> {
    v.filter(|v| v.len() == 3).map(|v| vec3(&v))
}

fn parse_spacing(v: Option<Vec<f64>>) -> Option<[f64; 2]> {
    v.filter(|v| v.len() == 2 && v.iter().all(|s| *s > 0.0))
        .map(|v| [v[0], v[1]])
}

fn rescale_of(obj: Option<&InMemDicomObject>) -> Option<Scaling> {
    let obj = obj?;
    let slope = get_f64s(obj, tags::RESCALE_SLOPE).and_then(|v| v.first().copied());
    let inter = get_f64s(obj, tags::RESCALE_INTERCEPT).and_then(|v| v.first().copied());
    if slope.is_none() && inter.is_none() {
        return None;
    }
    let slope = slope.filter(|s| *s != 0.0).unwrap_or(1.0);
    Some(Scaling {
        slope,
        inter: inter.unwrap_or(0.0),
    })
}

/// Reads the header of one file (up to the pixel data). `None` if it is not DICOM.
pub fn scan_file(path: &Path) -> Result<FileInfo, VolumeError> {
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    let obj = open_bytes(&bytes, path, Some(tags::PIXEL_DATA))?;
    info_from_object(&obj, path)
}

/// Runs dicom-rs code that may panic on damaged input; a panic becomes an error.
fn contained<T>(
    path: &Path,
    what: &str,
    f: impl FnOnce() -> Result<T, VolumeError>,
) -> Result<T, VolumeError> {
    crate::process::contain(f).unwrap_or_else(|panic| {
        Err(VolumeError::invalid(
            path,
            format!(
                "dicom-rs failed while {what} ({}): the file is damaged",
                short_name(&panic)
            ),
        ))
    })
}

/// Reads what [`FileInfo`] needs from an opened object.
pub fn info_from_object(obj: &DefaultDicomObject, path: &Path) -> Result<FileInfo, VolumeError> {
    let rows = get_int(obj, tags::ROWS);
    let cols = get_int(obj, tags::COLUMNS);
    let (Some(rows), Some(cols)) = (rows, cols) else {
        return Err(VolumeError::unsupported(
            path,
            "DICOM file without Rows/Columns: not an image (a report, structured data or DICOMDIR?)",
        ));
    };
    let dim = |v: i64, what: &str| {
        u32::try_from(v)
            .ok()
            .filter(|v| (1..=65535).contains(v))
            .ok_or_else(|| VolumeError::invalid(path, format!("{what} = {v} is not 1 … 65535")))
    };
    let (rows, cols) = (dim(rows, "Rows")?, dim(cols, "Columns")?);
    let frames = match get_int(obj, tags::NUMBER_OF_FRAMES) {
        None => 1,
        Some(n) => u32::try_from(n)
            .ok()
            .filter(|n| (1..=1_000_000).contains(n))
            .ok_or_else(|| {
                VolumeError::invalid(path, format!("NumberOfFrames = {n} is not 1 … 1000000"))
            })?,
    };
    let bits_allocated = get_int(obj, tags::BITS_ALLOCATED).unwrap_or(16);
    let bits_allocated = u16::try_from(bits_allocated)
        .ok()
        .filter(|b| matches!(b, 8 | 16 | 32))
        .ok_or_else(|| {
            VolumeError::unsupported(
                path,
                format!("BitsAllocated = {bits_allocated}: volao reads 8-, 16- and 32-bit pixels"),
            )
        })?;
    let bits_stored = get_int(obj, tags::BITS_STORED)
        .and_then(|b| u16::try_from(b).ok())
        .filter(|b| (1..=bits_allocated).contains(b))
        .unwrap_or(bits_allocated);
    let signed = get_int(obj, tags::PIXEL_REPRESENTATION) == Some(1);
    let samples_per_pixel = get_int(obj, tags::SAMPLES_PER_PIXEL)
        .and_then(|s| u16::try_from(s).ok())
        .unwrap_or(1);
    let photometric = get_str(obj, tags::PHOTOMETRIC_INTERPRETATION).unwrap_or_default();
    let series_uid = get_str(obj, tags::SERIES_INSTANCE_UID).unwrap_or_default();
    let sop_uid = get_str(obj, tags::SOP_INSTANCE_UID).unwrap_or_default();
    let top_position = parse_position(get_f64s(obj, tags::IMAGE_POSITION_PATIENT));
    let top_orientation = parse_orientation(get_f64s(obj, tags::IMAGE_ORIENTATION_PATIENT));
    let top_spacing = parse_spacing(get_f64s(obj, tags::PIXEL_SPACING));
    let top_rescale = rescale_of(Some(obj)).unwrap_or(Scaling::IDENTITY);
    let instance_number = get_int(obj, tags::INSTANCE_NUMBER);
    let slice_thickness = get_f64s(obj, tags::SLICE_THICKNESS)
        .and_then(|v| v.first().copied())
        .filter(|t| *t > 0.0);
    let functional = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .is_some()
        || obj.get(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE).is_some();
    let slices = (0..frames)
        .map(|frame| {
            if !functional {
                return Slice {
                    file: 0,
                    frame,
                    rows,
                    cols,
                    // One position for several frames describes only the first.
                    position: if frames == 1 { top_position } else { None },
                    orientation: top_orientation,
                    pixel_spacing: top_spacing,
                    rescale: top_rescale,
                    instance_number,
                };
            }
            let g = |seq| group(obj, frame, seq);
            Slice {
                file: 0,
                frame,
                rows,
                cols,
                position: g(tags::PLANE_POSITION_SEQUENCE)
                    .and_then(|o| parse_position(get_f64s(o, tags::IMAGE_POSITION_PATIENT))),
                orientation: g(tags::PLANE_ORIENTATION_SEQUENCE)
                    .and_then(|o| parse_orientation(get_f64s(o, tags::IMAGE_ORIENTATION_PATIENT)))
                    .or(top_orientation),
                pixel_spacing: g(tags::PIXEL_MEASURES_SEQUENCE)
                    .and_then(|o| parse_spacing(get_f64s(o, tags::PIXEL_SPACING)))
                    .or(top_spacing),
                rescale: rescale_of(g(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE))
                    .unwrap_or(top_rescale),
                instance_number,
            }
        })
        .collect();
    Ok(FileInfo {
        path: path.to_owned(),
        series_uid,
        sop_uid,
        series_description: get_str(obj, tags::SERIES_DESCRIPTION).unwrap_or_default(),
        modality: get_str(obj, tags::MODALITY).unwrap_or_default(),
        transfer_syntax: obj
            .meta()
            .transfer_syntax()
            .trim_end_matches('\0')
            .to_owned(),
        frames,
        bits_allocated,
        bits_stored,
        signed,
        samples_per_pixel,
        photometric,
        slice_thickness,
        slices,
    })
}

/// The transfer syntax's name, and whether dicom-rs (as built) decodes it.
pub fn transfer_syntax(uid: &str) -> (String, bool) {
    use dicom_encoding::TransferSyntaxIndex;
    match dicom_transfer_syntax_registry::TransferSyntaxRegistry.get(uid) {
        Some(ts) => (format!("{} ({uid})", ts.name()), ts.can_decode_all()),
        None => (format!("unknown transfer syntax {uid}"), false),
    }
}

fn is_dicom_file(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && has_dicm_magic(&head)
}

/// Files of a folder that carry the DICOM magic (not recursive), in name order.
pub fn list_folder(dir: &Path) -> Result<Vec<PathBuf>, VolumeError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| VolumeError::io(dir, e))?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    Ok(files.into_par_iter().filter(|p| is_dicom_file(p)).collect())
}

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
        super::fix_spacing(
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
    super::fix_spacing(
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

/// Which series to load: `None` = the one with most slices.
fn choose<'a>(
    series: &'a [Series],
    want: Option<&str>,
    path: &Path,
) -> Result<&'a Series, VolumeError> {
    let Some(want) = want else {
        return series
            .first()
            .ok_or_else(|| VolumeError::invalid(path, "no DICOM images found"));
    };
    if let Ok(k) = want.parse::<usize>() {
        return series.get(k).ok_or_else(|| {
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
    series.iter().find(|s| s.id == want).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "--series {}: no such SeriesInstanceUID here (`volao info` lists them)",
                short_name(want)
            ),
        )
    })
}

/// One line per series candidate, for `volao info` and warnings.
pub fn describe_series(series: &[Series], chosen: &str) -> String {
    series
        .iter()
        .enumerate()
        .map(|(k, s)| {
            format!(
                "[{k}]{} {} — {} {}×{} slice{}{}",
                if s.id == chosen { "*" } else { "" },
                s.id,
                s.slices.len(),
                s.slices[0].cols,
                s.slices[0].rows,
                if s.slices.len() == 1 { "" } else { "s" },
                if s.description.is_empty() && s.modality.is_empty() {
                    String::new()
                } else {
                    format!(", {} {}", s.modality, s.description)
                }
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What a loaded series looked like (for `Format` and `info`).
#[derive(Debug, Clone)]
pub struct DicomInfo {
    pub files: usize,
    pub frames: usize,
    pub transfer_syntax: String,
    pub series_count: usize,
}

/// Loads the series at `path` (a folder or one of its files).
pub fn load(
    path: &Path,
    series_wanted: Option<&str>,
    max_bytes: u64,
    warnings: &mut Vec<String>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Volume, DicomInfo, PathBuf), VolumeError> {
    let infos: Vec<FileInfo> = if path.is_dir() {
        let files = list_folder(path)?;
        if files.is_empty() {
            return Err(VolumeError::invalid(
                path,
                "folder holds no DICOM files (none has the DICM magic at byte 128)",
            ));
        }
        let (ok, bad): (Vec<_>, Vec<_>) = files
            .par_iter()
            .map(|f| scan_file(f))
            .collect::<Vec<_>>()
            .into_iter()
            .partition(|r| r.is_ok());
        for e in bad.into_iter().filter_map(|r| r.err()).take(5) {
            warnings.push(format!("skipping {e}"));
        }
        ok.into_iter().filter_map(|r| r.ok()).collect()
    } else {
        let me = scan_file(path)?;
        // A single-frame file brings its series from the same folder.
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
        if me.frames == 1 && !me.series_uid.is_empty() {
            let dir = dir.unwrap_or(Path::new("."));
            let others = list_folder(dir).unwrap_or_default();
            let mut infos: Vec<FileInfo> = others
                .par_iter()
                .filter(|p| !same_file(p, path))
                .filter_map(|p| scan_file(p).ok())
                .filter(|f| f.series_uid == me.series_uid && f.frames == 1)
                .collect();
            infos.insert(0, me);
            infos
        } else {
            vec![me]
        }
    };
    if infos.is_empty() {
        return Err(VolumeError::invalid(path, "no readable DICOM images found"));
    }
    let padded = std::sync::atomic::AtomicUsize::new(0);
    let decode = |k: usize| -> Result<Decoded, VolumeError> {
        let (obj, cut) = open_full(&infos[k])?;
        if cut {
            padded.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        decode_object(&obj, &infos[k])
    };
    let (volume, info, k) = assemble(
        &infos,
        series_wanted,
        path,
        max_bytes,
        warnings,
        &decode,
        progress,
    )?;
    let padded = padded.into_inner();
    if padded > 0 {
        warnings.push(format!(
            "{padded} {} bytes after the pixel data that are not DICOM (padding?); ignored",
            if padded == 1 {
                "file carries"
            } else {
                "files carry"
            }
        ));
    }
    Ok((volume, info, infos[k].path.clone()))
}

/// Opens a whole file. Some writers pad files after the pixel data (zeros), which
/// dicom-rs reads as a broken element: for uncompressed pixel data the file is then cut
/// right after the pixel data element and parsed again (`true` = it was cut).
fn open_full(info: &FileInfo) -> Result<(DefaultDicomObject, bool), VolumeError> {
    let p = &info.path;
    let bytes = std::fs::read(p).map_err(|e| VolumeError::io(p, e))?;
    let first_error = match open_bytes(&bytes, p, None) {
        Ok(obj) => return Ok((obj, false)),
        Err(e) => e,
    };
    let fail = || match &first_error {
        VolumeError::Invalid { message, .. } => {
            VolumeError::invalid(p, format!("cannot read the DICOM file ({message})"))
        }
        other => VolumeError::invalid(p, format!("cannot read the DICOM file ({other})")),
    };
    let s = info.slices.first().ok_or_else(fail)?;
    let expected = u64::from(s.rows)
        * u64::from(s.cols)
        * u64::from(info.frames)
        * u64::from(info.bits_allocated / 8);
    let end = pixel_data_end(&bytes, expected).ok_or_else(fail)?;
    let obj = open_bytes(&bytes[..end], p, None).map_err(|_| fail())?;
    Ok((obj, true))
}

/// Where a native (not encapsulated) Pixel Data element of `expected` bytes ends: its
/// header in explicit little/big endian or implicit VR, searched from the end.
fn pixel_data_end(bytes: &[u8], expected: u64) -> Option<usize> {
    let want = [expected, expected + 1];
    let fits = |at: usize, len: u64| {
        want.contains(&len)
            .then(|| at.checked_add(usize::try_from(len).ok()?))
            .flatten()
            .filter(|&end| end <= bytes.len())
    };
    let u32_le = |b: &[u8]| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let u32_be = |b: &[u8]| u64::from(u32::from_be_bytes([b[0], b[1], b[2], b[3]]));
    (0..bytes.len().saturating_sub(12)).rev().find_map(|i| {
        let h = &bytes[i..i + 12];
        if h[..4] == [0xe0, 0x7f, 0x10, 0x00] {
            if (h[4..6] == *b"OW" || h[4..6] == *b"OB") && h[6..8] == [0, 0] {
                return fits(i + 12, u32_le(&h[8..12]));
            }
            return fits(i + 8, u32_le(&h[4..8]));
        }
        if h[..4] == [0x7f, 0xe0, 0x00, 0x10] && (h[4..6] == *b"OW" || h[4..6] == *b"OB") {
            return fits(i + 12, u32_be(&h[8..12]));
        }
        None
    })
}

type Decoded = dicom_pixeldata::DecodedPixelData<'static>;

fn decode_object(obj: &DefaultDicomObject, info: &FileInfo) -> Result<Decoded, VolumeError> {
    contained(&info.path, "decoding the pixel data", || {
        decode_object_inner(obj, info)
    })
}

fn decode_object_inner(obj: &DefaultDicomObject, info: &FileInfo) -> Result<Decoded, VolumeError> {
    let px = obj.decode_pixel_data().map_err(|e| {
        VolumeError::invalid(
            &info.path,
            format!(
                "cannot decode the pixel data (transfer syntax {}): {e}",
                transfer_syntax(&info.transfer_syntax).0
            ),
        )
    })?;
    Ok(px.to_owned())
}

/// Loads in-memory DICOM files as one series (fuzzing, mutation tests); `path` is for
/// messages only.
pub fn load_bytes(
    files: &[&[u8]],
    series_wanted: Option<&str>,
    max_bytes: u64,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Volume, VolumeError> {
    let mut objs = Vec::new();
    let mut infos = Vec::new();
    for (k, bytes) in files.iter().enumerate() {
        let name = path.join(format!("file{k}"));
        let Ok(obj) = open_bytes(bytes, &name, None) else {
            continue;
        };
        let Ok(info) = info_from_object(&obj, &name) else {
            continue;
        };
        objs.push(obj);
        infos.push(info);
    }
    if infos.is_empty() {
        return Err(VolumeError::invalid(path, "no readable DICOM images found"));
    }
    let decode = |k: usize| decode_object(&objs[k], &infos[k]);
    let (volume, _, _) = assemble(
        &infos,
        series_wanted,
        path,
        max_bytes,
        warnings,
        &decode,
        &mut |_, _| {},
    )?;
    Ok(volume)
}

fn open_bytes(
    bytes: &[u8],
    path: &Path,
    until: Option<Tag>,
) -> Result<DefaultDicomObject, VolumeError> {
    let body = bytes
        .get(128..)
        .filter(|_| has_dicm_magic(bytes))
        .ok_or_else(|| VolumeError::invalid(path, "no DICM magic at byte 128"))?;
    check_declared_lengths(bytes).map_err(|m| VolumeError::invalid(path, m))?;
    let mut opts = OpenFileOptions::new().read_preamble(dicom_object::file::ReadPreamble::Never);
    if let Some(t) = until {
        opts = opts.read_until(t);
    }
    contained(path, "reading the file", || {
        opts.from_reader(body)
            .map_err(|e| VolumeError::invalid(path, format!("not a readable DICOM file ({e})")))
    })
}

/// Groups, orders and decodes the images of `infos` into one volume; `decode(k)` gives
/// the pixels of file `k`. Returns the volume, a summary and the first file used.
fn assemble(
    infos: &[FileInfo],
    series_wanted: Option<&str>,
    path: &Path,
    max_bytes: u64,
    warnings: &mut Vec<String>,
    decode_file: &(dyn Fn(usize) -> Result<Decoded, VolumeError> + Sync),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Volume, DicomInfo, usize), VolumeError> {
    let series = group_series(infos, warnings);
    let chosen = choose(&series, series_wanted, path)?;
    let files_used: std::collections::BTreeSet<usize> =
        chosen.slices.iter().map(|s| s.file).collect();
    let first = &infos[chosen.slices[0].file];
    if series.len() > 1 {
        warnings.push(format!(
            "{} series here; loading [{}] {} (choose another with --series N or UID; `volao info` lists them)",
            series.len(),
            series.iter().position(|s| s.id == chosen.id).unwrap_or(0),
            chosen.id
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
    for &k in &files_used {
        let (name, ok) = transfer_syntax(&infos[k].transfer_syntax);
        if !ok {
            return Err(VolumeError::unsupported(
                &infos[k].path,
                format!(
                    "transfer syntax {name} cannot be decoded by this build (dicom-rs without system libraries; JPEG-LS needs CharLS) — convert it with e.g. `gdcmconv --raw` or dcm2niix"
                ),
            ));
        }
    }
    let geo = geometry(&chosen.slices, first.slice_thickness, path, warnings)?;
    let (rows, cols) = (chosen.slices[0].rows, chosen.slices[0].cols);
    let nz = geo.order.len();
    let dims = [cols as usize, rows as usize, nz];
    let bytes_per = (first.bits_allocated / 8) as usize;
    let slice_px = rows as usize * cols as usize;
    let total = (slice_px as u64)
        .checked_mul(nz as u64)
        .and_then(|v| v.checked_mul(bytes_per as u64))
        .unwrap_or(u64::MAX);
    if total > max_bytes {
        return Err(VolumeError::TooLarge {
            path: path.to_owned(),
            dims: fmt_dims(dims),
            ty: format!("{}-bit", first.bits_allocated),
            bytes: fmt_bytes(total),
            limit: fmt_bytes(max_bytes),
        });
    }
    let slice_bytes = slice_px * bytes_per;
    let mut raw: Vec<u8> = Vec::new();
    raw.try_reserve_exact(total as usize).map_err(|_| {
        VolumeError::invalid(
            path,
            format!("cannot allocate {} for the voxels", fmt_bytes(total)),
        )
    })?;
    raw.resize(total as usize, 0);
    // z → (file, frame)
    let z_src: Vec<(usize, u32)> = geo
        .order
        .iter()
        .map(|&i| (chosen.slices[i].file, chosen.slices[i].frame))
        .collect();
    let copy_frame = |px: &dicom_pixeldata::DecodedPixelData<'_>,
                      k: usize,
                      frame: u32,
                      dst: &mut [u8]|
     -> Result<(), VolumeError> {
        let p = &infos[k].path;
        if px.rows() != rows || px.columns() != cols || px.bits_allocated() != first.bits_allocated
        {
            return Err(VolumeError::invalid(
                p,
                format!(
                    "decoded image is {}×{} {}-bit, the series is {cols}×{rows} {}-bit",
                    px.columns(),
                    px.rows(),
                    px.bits_allocated(),
                    first.bits_allocated
                ),
            ));
        }
        let start = frame as usize * slice_bytes;
        let src =
            px.data()
                .get(start..start + slice_bytes)
                .ok_or_else(|| VolumeError::Truncated {
                    path: p.clone(),
                    what: format!("pixel data of frame {frame}"),
                    expected: (start + slice_bytes) as u64,
                    actual: px.data().len() as u64,
                })?;
        dst.copy_from_slice(src);
        Ok(())
    };
    let single_frame = files_used.iter().all(|&k| infos[k].frames == 1);
    let done = std::sync::atomic::AtomicU64::new(0);
    if single_frame {
        raw.par_chunks_mut(slice_bytes)
            .zip(z_src.par_iter())
            .try_for_each(|(dst, &(k, frame))| {
                let px = decode_file(k)?;
                copy_frame(&px, k, frame, dst)?;
                done.fetch_add(slice_bytes as u64, std::sync::atomic::Ordering::Relaxed);
                Ok::<(), VolumeError>(())
            })?;
        progress(total, total);
    } else {
        for &k in &files_used {
            let px = decode_file(k)?;
            for (z, &(kk, frame)) in z_src.iter().enumerate() {
                if kk == k {
                    copy_frame(
                        &px,
                        k,
                        frame,
                        &mut raw[z * slice_bytes..(z + 1) * slice_bytes],
                    )?;
                }
            }
            progress(
                done.fetch_add(0, std::sync::atomic::Ordering::Relaxed),
                total,
            );
        }
        progress(total, total);
    }
    let data = to_voxels(raw, first.bits_allocated, first.bits_stored, first.signed);
    if first.photometric == "MONOCHROME1" {
        warnings.push(
            "MONOCHROME1: low values display white on a radiograph; volao shows the stored values as they are"
                .into(),
        );
    }
    let rescales: Vec<Scaling> = geo
        .order
        .iter()
        .map(|&i| chosen.slices[i].rescale)
        .collect();
    let (data, scaling) = if rescales.iter().all(|r| *r == rescales[0]) {
        (data, rescales[0])
    } else {
        warnings.push(
            "slices have different RescaleSlope/Intercept: values converted to f32 in physical units"
                .into(),
        );
        (
            apply_per_slice(&data, &rescales, slice_px),
            Scaling::IDENTITY,
        )
    };
    let (scaling, data) = super::check_scaling(scaling, data, path, warnings);
    let mut volume = Volume {
        dims,
        spacing: geo.spacing,
        data,
        scaling,
        orientation: geo.orientation,
        descriptions: Vec::new(),
    };
    let (ts_name, _) = transfer_syntax(&first.transfer_syntax);
    volume
        .descriptions
        .push(("transfer syntax".into(), ts_name.clone()));
    if !first.modality.is_empty() || !first.series_description.is_empty() {
        volume.descriptions.push((
            "series".into(),
            format!("{} {}", first.modality, first.series_description)
                .trim()
                .to_owned(),
        ));
    }
    volume
        .descriptions
        .push(("series uid".into(), chosen.id.clone()));
    if series.len() > 1 {
        volume
            .descriptions
            .push(("all series".into(), describe_series(&series, &chosen.id)));
    }
    let info = DicomInfo {
        files: files_used.len(),
        frames: nz,
        transfer_syntax: ts_name,
        series_count: series.len(),
    };
    Ok((volume, info, chosen.slices[0].file))
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Native-endian samples → typed voxels, masked to BitsStored (sign-extended if signed).
pub fn to_voxels(raw: Vec<u8>, bits_allocated: u16, bits_stored: u16, signed: bool) -> VoxelData {
    let shift = bits_allocated - bits_stored.min(bits_allocated);
    match (bits_allocated, signed) {
        (8, false) => VoxelData::U8(raw.into_iter().map(|v| v & (0xffu8 >> shift)).collect()),
        (8, true) => VoxelData::I8(
            raw.into_iter()
                .map(|v| ((v << shift) as i8) >> shift)
                .collect(),
        ),
        (16, false) => VoxelData::U16(
            raw.chunks_exact(2)
                .map(|b| u16::from_ne_bytes([b[0], b[1]]) & (0xffffu16 >> shift))
                .collect(),
        ),
        (16, true) => VoxelData::I16(
            raw.chunks_exact(2)
                .map(|b| ((u16::from_ne_bytes([b[0], b[1]]) << shift) as i16) >> shift)
                .collect(),
        ),
        (_, false) => VoxelData::U32(
            raw.chunks_exact(4)
                .map(|b| u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) & (u32::MAX >> shift))
                .collect(),
        ),
        (_, true) => VoxelData::I32(
            raw.chunks_exact(4)
                .map(|b| ((u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) << shift) as i32) >> shift)
                .collect(),
        ),
    }
}

fn apply_per_slice(data: &VoxelData, rescales: &[Scaling], slice_px: usize) -> VoxelData {
    VoxelData::F32(
        (0..data.len())
            .map(|i| rescales[i / slice_px].apply(data.get_f64(i)) as f32)
            .collect(),
    )
}

/// Series assembly from already-scanned headers, without pixels (fuzzing, tests): the
/// chosen series' id, dims and geometry.
pub fn assemble_headers(
    files: &[FileInfo],
    series_wanted: Option<&str>,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<(String, [usize; 3], Geometry), VolumeError> {
    let series = group_series(files, warnings);
    let chosen = choose(&series, series_wanted, path)?;
    let thickness = files[chosen.slices[0].file].slice_thickness;
    let geo = geometry(&chosen.slices, thickness, path, warnings)?;
    let s = &chosen.slices[0];
    Ok((
        chosen.id.clone(),
        [s.cols as usize, s.rows as usize, geo.order.len()],
        geo,
    ))
}

/// Parses one in-memory DICOM file's header (fuzzing).
pub fn scan_bytes(bytes: &[u8], path: &Path) -> Result<FileInfo, VolumeError> {
    let obj = open_bytes(bytes, path, Some(tags::PIXEL_DATA))?;
    info_from_object(&obj, path)
}

/// Checks, before dicom-rs sees a file, that no element claims more bytes than the
/// file holds: dicom-rs reserves an element's declared length before reading it, so a
/// 1 KiB file claiming a 4 GiB element would make it allocate 4 GiB (found by fuzzing).
/// Walks the meta group and, for little/big endian explicit and implicit VR, the data
/// set with its sequences and items. Returns the first impossible claim; stops quietly
/// where it cannot follow the encoding (deflate, an unknown VR), leaving those to
/// dicom-rs.
pub fn check_declared_lengths(bytes: &[u8]) -> Result<(), String> {
    let Some(body) = bytes.get(132..).filter(|_| has_dicm_magic(bytes)) else {
        return Ok(());
    };
    let mut w = Walker {
        b: body,
        explicit: true,
        little: true,
    };
    // The meta group is explicit little endian; then the data set's own encoding.
    let mut at = 0usize;
    let mut ts_uid = String::new();
    while at + 8 <= body.len() && u16::from_le_bytes([body[at], body[at + 1]]) == 0x0002 {
        let next = match w.element(at, body.len(), 0, false)? {
            Some(next) => next,
            None => return Ok(()),
        };
        if u16::from_le_bytes([body[at + 2], body[at + 3]]) == 0x0010 {
            ts_uid = String::from_utf8_lossy(&body[at + 8..next]).into_owned();
        }
        at = next;
    }
    let (explicit, little) = match ts_uid.trim_end_matches(['\0', ' ']) {
        "1.2.840.10008.1.2" => (false, true),
        "1.2.840.10008.1.2.2" => (true, false),
        "1.2.840.10008.1.2.1.99" => return Ok(()), // deflated: not followed
        _ => (true, true),
    };
    w.explicit = explicit;
    w.little = little;
    w.walk(at, body.len(), 0, false).map(|_| ())
}

struct Walker<'a> {
    b: &'a [u8],
    explicit: bool,
    little: bool,
}

const LONG_VRS: [&[u8; 2]; 13] = [
    b"OB", b"OD", b"OF", b"OL", b"OV", b"OW", b"SQ", b"SV", b"UC", b"UN", b"UR", b"UT", b"UV",
];

impl Walker<'_> {
    fn u16(&self, at: usize) -> u16 {
        let v = [self.b[at], self.b[at + 1]];
        if self.little {
            u16::from_le_bytes(v)
        } else {
            u16::from_be_bytes(v)
        }
    }

    fn u32(&self, at: usize) -> u32 {
        let v = [self.b[at], self.b[at + 1], self.b[at + 2], self.b[at + 3]];
        if self.little {
            u32::from_le_bytes(v)
        } else {
            u32::from_be_bytes(v)
        }
    }

    /// Elements (or, with `fragments`, the items of encapsulated pixel data) from `at`
    /// to `end` or to a delimiter: `Ok(Some(pos))` after them, `Ok(None)` where the walk
    /// cannot follow.
    fn walk(
        &self,
        mut at: usize,
        end: usize,
        depth: usize,
        fragments: bool,
    ) -> Result<Option<usize>, String> {
        if depth > 32 {
            return Ok(None);
        }
        while at + 8 <= end {
            let (g, e) = (self.u16(at), self.u16(at + 2));
            if g == 0xfffe && (e == 0xe00d || e == 0xe0dd) {
                return Ok(Some(at + 8)); // item / sequence delimiter
            }
            match self.element(at, end, depth, fragments)? {
                Some(next) => at = next,
                None => return Ok(None),
            }
        }
        Ok(Some(at))
    }

    fn element(
        &self,
        at: usize,
        end: usize,
        depth: usize,
        fragments: bool,
    ) -> Result<Option<usize>, String> {
        if at + 8 > end {
            return Ok(None);
        }
        let (g, e) = (self.u16(at), self.u16(at + 2));
        let item = g == 0xfffe && e == 0xe000;
        if fragments && !item {
            return Ok(None);
        }
        let (len, head, vr) = if g == 0xfffe {
            (self.u32(at + 4), 8, None)
        } else if self.explicit {
            let vr = [self.b[at + 4], self.b[at + 5]];
            if !vr.iter().all(u8::is_ascii_uppercase) {
                return Ok(None);
            }
            if LONG_VRS.contains(&&vr) {
                if at + 12 > end {
                    return Ok(None);
                }
                (self.u32(at + 8), 12, Some(vr))
            } else {
                (u32::from(self.u16(at + 6)), 8, Some(vr))
            }
        } else {
            (self.u32(at + 4), 8, None)
        };
        let start = at + head;
        let pixel_data = (g, e) == (0x7fe0, 0x0010);
        if len == u32::MAX {
            // Undefined length: encapsulated pixel data (fragments), a sequence, or an
            // item of a sequence (elements).
            return self.walk(start, end, depth + 1, pixel_data);
        }
        let len = len as usize;
        if len > end.saturating_sub(start) {
            return Err(format!(
                "element ({g:04X},{e:04X}) claims {len} bytes but only {} remain in the file: truncated or damaged",
                end.saturating_sub(start)
            ));
        }
        let sequence = vr == Some(*b"SQ");
        if sequence || (item && !fragments) {
            self.walk(start, start + len, depth + 1, false)?;
        }
        Ok(Some(start + len))
    }
}
