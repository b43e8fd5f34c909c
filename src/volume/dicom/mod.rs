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

mod header;
mod lengths;
mod series;

pub use header::*;
use header::{contained, open_bytes};
pub use lengths::*;
pub use series::*;

use crate::volume::{Reading, Scaling, Volume, VolumeError, VoxelData, escape_controls, fmt_bytes};
use dicom_dictionary_std::tags;
use dicom_object::DefaultDicomObject;
use dicom_pixeldata::PixelDecoder;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

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
    mut reading: Reading<'_>,
) -> Result<(Volume, DicomInfo, PathBuf), VolumeError> {
    let warnings = &mut *reading.warnings;
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
    let (volume, info, k) = assemble(&infos, series_wanted, path, &decode, &mut reading)?;
    let padded = padded.into_inner();
    if padded > 0 {
        reading.warnings.push(format!(
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
    let mut reading = Reading {
        max_bytes,
        warnings,
        progress: &mut |_, _| {},
    };
    let (volume, _, _) = assemble(&infos, series_wanted, path, &decode, &mut reading)?;
    Ok(volume)
}

/// Groups, orders and decodes the images of `infos` into one volume; `decode(k)` gives
/// the pixels of file `k`. Returns the volume, a summary and the first file used.
fn assemble(
    infos: &[FileInfo],
    series_wanted: Option<&str>,
    path: &Path,
    decode_file: &(dyn Fn(usize) -> Result<Decoded, VolumeError> + Sync),
    reading: &mut Reading<'_>,
) -> Result<(Volume, DicomInfo, usize), VolumeError> {
    let warnings = &mut *reading.warnings;
    let progress = &mut *reading.progress;
    let Assembly {
        series,
        chosen,
        files_used,
        geometry: geo,
        dims,
        bytes: total,
    } = plan(infos, series_wanted, path, reading.max_bytes, warnings)?;
    let chosen = &series[chosen];
    let first = &infos[chosen.slices[0].file];
    let (rows, cols) = (chosen.slices[0].rows, chosen.slices[0].cols);
    let bytes_per = (first.bits_allocated / 8) as usize;
    let slice_px = rows as usize * cols as usize;
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
            escape_controls(format!("{} {}", first.modality, first.series_description).trim()),
        ));
    }
    volume
        .descriptions
        .push(("series uid".into(), escape_controls(&chosen.id)));
    if series.len() > 1 {
        volume
            .descriptions
            .push(("all series".into(), describe_series(&series, &chosen.id)));
    }
    let info = DicomInfo {
        files: files_used.len(),
        frames: dims[2],
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

/// Parses one in-memory DICOM file's header (fuzzing).
pub fn scan_bytes(bytes: &[u8], path: &Path) -> Result<FileInfo, VolumeError> {
    let obj = open_bytes(bytes, path, Some(tags::PIXEL_DATA))?;
    info_from_object(&obj, path)
}
