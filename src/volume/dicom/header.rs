//! One DICOM file's header as far as volao needs it: the image's size, geometry,
//! rescale and pixel format, read up to the pixel data; the folder listing.

use super::lengths::{check_declared_lengths, has_dicm_magic};
use crate::volume::{Scaling, VolumeError, short_name};
use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions, Tag};
use glam::DVec3;
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

/// The header values of one file that volao uses, as dicom-rs read them and before any
/// check ([`FileInfo::from_tags`] makes them a [`FileInfo`]). Plain data, so series
/// assembly can be tested and fuzzed without DICOM files or dicom-rs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HeaderTags {
    pub rows: Option<i64>,
    pub cols: Option<i64>,
    pub number_of_frames: Option<i64>,
    pub bits_allocated: Option<i64>,
    pub bits_stored: Option<i64>,
    pub pixel_representation: Option<i64>,
    pub samples_per_pixel: Option<i64>,
    /// Text values are trimmed of spaces and NULs; empty ones are `None`.
    pub photometric: Option<String>,
    pub series_uid: Option<String>,
    pub sop_uid: Option<String>,
    pub series_description: Option<String>,
    pub modality: Option<String>,
    pub transfer_syntax: String,
    pub instance_number: Option<i64>,
    pub slice_thickness: Option<Vec<f64>>,
    /// The top-level plane and rescale elements.
    pub plane: PlaneTags,
    /// Enhanced (functional groups) files: frame k's values, from its per-frame
    /// functional group or else the shared one. `None` without functional groups.
    pub frames: Option<Vec<PlaneTags>>,
}

/// Where one image lies and how its values scale, as stored (multi-valued numbers as
/// read, not yet checked for count or finiteness).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlaneTags {
    pub position: Option<Vec<f64>>,
    pub orientation: Option<Vec<f64>>,
    pub pixel_spacing: Option<Vec<f64>>,
    pub rescale_slope: Option<Vec<f64>>,
    pub rescale_intercept: Option<Vec<f64>>,
}

fn get_str(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let s = obj.get(tag)?.to_str().ok()?;
    let s = s.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    (!s.is_empty()).then(|| s.to_owned())
}

fn get_f64s(obj: &InMemDicomObject, tag: Tag) -> Option<Vec<f64>> {
    obj.get(tag)?.to_multi_float64().ok()
}

/// A multi-valued number only when every value is finite.
fn finite(v: &Option<Vec<f64>>) -> Option<Vec<f64>> {
    v.as_ref()
        .filter(|v| v.iter().all(|x| x.is_finite()))
        .cloned()
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

/// RescaleSlope/Intercept of a plane; `None` when it has neither.
fn rescale_of(p: &PlaneTags) -> Option<Scaling> {
    let slope = finite(&p.rescale_slope).and_then(|v| v.first().copied());
    let inter = finite(&p.rescale_intercept).and_then(|v| v.first().copied());
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
pub(super) fn contained<T>(
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
    FileInfo::from_tags(&tags_of_object(obj), path)
}

fn plane_of(obj: Option<&InMemDicomObject>, tag: Tag) -> Option<Vec<f64>> {
    obj.and_then(|o| get_f64s(o, tag))
}

/// The header values volao uses, read from an opened object without checking them.
pub fn tags_of_object(obj: &DefaultDicomObject) -> HeaderTags {
    let rows = get_int(obj, tags::ROWS);
    let cols = get_int(obj, tags::COLUMNS);
    let number_of_frames = get_int(obj, tags::NUMBER_OF_FRAMES);
    let functional = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .is_some()
        || obj.get(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE).is_some();
    // Per-frame values only for a frame count that FileInfo::from_tags accepts.
    let frame_count = match number_of_frames {
        _ if rows.is_none() || cols.is_none() => 0,
        None => 1,
        Some(n) => u32::try_from(n)
            .ok()
            .filter(|n| (1..=MAX_FRAMES).contains(n))
            .unwrap_or(0),
    };
    let frames = functional.then(|| {
        (0..frame_count)
            .map(|frame| {
                let g = |seq| group(obj, frame, seq);
                let rescale = g(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE);
                PlaneTags {
                    position: plane_of(
                        g(tags::PLANE_POSITION_SEQUENCE),
                        tags::IMAGE_POSITION_PATIENT,
                    ),
                    orientation: plane_of(
                        g(tags::PLANE_ORIENTATION_SEQUENCE),
                        tags::IMAGE_ORIENTATION_PATIENT,
                    ),
                    pixel_spacing: plane_of(g(tags::PIXEL_MEASURES_SEQUENCE), tags::PIXEL_SPACING),
                    rescale_slope: plane_of(rescale, tags::RESCALE_SLOPE),
                    rescale_intercept: plane_of(rescale, tags::RESCALE_INTERCEPT),
                }
            })
            .collect()
    });
    HeaderTags {
        rows,
        cols,
        number_of_frames,
        bits_allocated: get_int(obj, tags::BITS_ALLOCATED),
        bits_stored: get_int(obj, tags::BITS_STORED),
        pixel_representation: get_int(obj, tags::PIXEL_REPRESENTATION),
        samples_per_pixel: get_int(obj, tags::SAMPLES_PER_PIXEL),
        photometric: get_str(obj, tags::PHOTOMETRIC_INTERPRETATION),
        series_uid: get_str(obj, tags::SERIES_INSTANCE_UID),
        sop_uid: get_str(obj, tags::SOP_INSTANCE_UID),
        series_description: get_str(obj, tags::SERIES_DESCRIPTION),
        modality: get_str(obj, tags::MODALITY),
        transfer_syntax: obj
            .meta()
            .transfer_syntax()
            .trim_end_matches('\0')
            .to_owned(),
        instance_number: get_int(obj, tags::INSTANCE_NUMBER),
        slice_thickness: get_f64s(obj, tags::SLICE_THICKNESS),
        plane: PlaneTags {
            position: get_f64s(obj, tags::IMAGE_POSITION_PATIENT),
            orientation: get_f64s(obj, tags::IMAGE_ORIENTATION_PATIENT),
            pixel_spacing: get_f64s(obj, tags::PIXEL_SPACING),
            rescale_slope: get_f64s(obj, tags::RESCALE_SLOPE),
            rescale_intercept: get_f64s(obj, tags::RESCALE_INTERCEPT),
        },
        frames,
    }
}

/// Most frames a multi-frame file may claim.
pub const MAX_FRAMES: u32 = 1_000_000;

impl FileInfo {
    /// Checks a header's values and derives the images (slices) it holds; `path` is the
    /// file they came from.
    pub fn from_tags(t: &HeaderTags, path: &Path) -> Result<FileInfo, VolumeError> {
        let (Some(rows), Some(cols)) = (t.rows, t.cols) else {
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
        let frames = match t.number_of_frames {
            None => 1,
            Some(n) => u32::try_from(n)
                .ok()
                .filter(|n| (1..=MAX_FRAMES).contains(n))
                .ok_or_else(|| {
                    VolumeError::invalid(
                        path,
                        format!("NumberOfFrames = {n} is not 1 … {MAX_FRAMES}"),
                    )
                })?,
        };
        let bits_allocated = t.bits_allocated.unwrap_or(16);
        let bits_allocated = u16::try_from(bits_allocated)
            .ok()
            .filter(|b| matches!(b, 8 | 16 | 32))
            .ok_or_else(|| {
                VolumeError::unsupported(
                    path,
                    format!(
                        "BitsAllocated = {bits_allocated}: volao reads 8-, 16- and 32-bit pixels"
                    ),
                )
            })?;
        let bits_stored = t
            .bits_stored
            .and_then(|b| u16::try_from(b).ok())
            .filter(|b| (1..=bits_allocated).contains(b))
            .unwrap_or(bits_allocated);
        let signed = t.pixel_representation == Some(1);
        let samples_per_pixel = t
            .samples_per_pixel
            .and_then(|s| u16::try_from(s).ok())
            .unwrap_or(1);
        let top_position = parse_position(finite(&t.plane.position));
        let top_orientation = parse_orientation(finite(&t.plane.orientation));
        let top_spacing = parse_spacing(finite(&t.plane.pixel_spacing));
        let top_rescale = rescale_of(&t.plane).unwrap_or(Scaling::IDENTITY);
        let instance_number = t.instance_number;
        let slice_thickness = finite(&t.slice_thickness)
            .and_then(|v| v.first().copied())
            .filter(|t| *t > 0.0);
        let slices = (0..frames)
            .map(|frame| {
                let Some(per_frame) = &t.frames else {
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
                };
                let g = per_frame.get(frame as usize).cloned().unwrap_or_default();
                Slice {
                    file: 0,
                    frame,
                    rows,
                    cols,
                    position: parse_position(finite(&g.position)),
                    orientation: parse_orientation(finite(&g.orientation)).or(top_orientation),
                    pixel_spacing: parse_spacing(finite(&g.pixel_spacing)).or(top_spacing),
                    rescale: rescale_of(&g).unwrap_or(top_rescale),
                    instance_number,
                }
            })
            .collect();
        Ok(FileInfo {
            path: path.to_owned(),
            series_uid: t.series_uid.clone().unwrap_or_default(),
            sop_uid: t.sop_uid.clone().unwrap_or_default(),
            series_description: t.series_description.clone().unwrap_or_default(),
            modality: t.modality.clone().unwrap_or_default(),
            transfer_syntax: t.transfer_syntax.clone(),
            frames,
            bits_allocated,
            bits_stored,
            signed,
            samples_per_pixel,
            photometric: t.photometric.clone().unwrap_or_default(),
            slice_thickness,
            slices,
        })
    }
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

pub(super) fn open_bytes(
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
