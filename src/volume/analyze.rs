//! Analyze 7.5 `.hdr`/`.img` pairs (SPM): a 348-byte header without the NIfTI magic.
//!
//! Read as nibabel reads them (`Spm2AnalyzeImage`): dim, datatype and pixdim as in
//! NIfTI-1, `funused1`/`funused2` as slope/intercept, and no orientation — the voxel
//! axes are assumed to run LAS (radiological: x towards the patient's left), with the
//! SPM `origin` field (1-based voxel) or else the volume centre at world (0, 0, 0).

use super::nifti::{self, Header, Layout};
use super::orient::{AffineSource, Orientation};
use super::{Scaling, Volume, VolumeError};
use glam::{DMat3, DVec3};
use std::path::Path;

/// Whether a 348-byte header is Analyze 7.5: `sizeof_hdr` 348 in either byte order and
/// no NIfTI magic at 344.
pub fn is_analyze(head: &[u8]) -> bool {
    if head.len() < 348 {
        return false;
    }
    let first = [head[0], head[1], head[2], head[3]];
    let size_ok = i32::from_le_bytes(first) == 348 || i32::from_be_bytes(first) == 348;
    let magic = &head[344..348];
    size_ok && magic != b"n+1\0" && magic != b"ni1\0"
}

/// Parses an Analyze 7.5 header (no magic) into the NIfTI header type.
pub fn parse_header(buf: &[u8; 348], path: &Path) -> Result<(Header, [i16; 3]), VolumeError> {
    let little_endian = i32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]) == 348;
    if !little_endian && i32::from_be_bytes([buf[0], buf[1], buf[2], buf[3]]) != 348 {
        return Err(VolumeError::invalid(
            path,
            "not an Analyze 7.5 header (sizeof_hdr is not 348)",
        ));
    }
    let f = super::fields::Fields::new(buf, little_endian);
    let f32_at = |at: usize| f64::from(f.f32(at));
    let header = Header {
        version: 1,
        little_endian,
        dim: std::array::from_fn(|k| i64::from(f.i16(40 + 2 * k))),
        datatype: f.i16(70),
        pixdim: std::array::from_fn(|k| f32_at(76 + 4 * k)),
        vox_offset: f32_at(108),
        scl_slope: f32_at(112),
        scl_inter: f32_at(116),
        qform_code: 0,
        sform_code: 0,
        quatern: [0.0; 3],
        qoffset: [0.0; 3],
        srow: [[0.0; 4]; 3],
        descrip: f.text(148, 80),
        intent_code: 0,
        single_file: false,
    };
    let origin = [f.i16(253), f.i16(255), f.i16(257)];
    Ok((header, origin))
}

/// nibabel's `Spm99AnalyzeHeader.get_origin_affine`: LAS with the SPM origin, or the
/// centre of the volume when the origin is unset or out of range.
pub fn orientation(dims: [usize; 3], spacing: [f32; 3], origin: [i16; 3]) -> Orientation {
    let d = dims.map(|n| n as f64);
    let o = origin.map(f64::from);
    let usable = o.iter().any(|&v| v != 0.0) && (0..3).all(|i| o[i] > -d[i] && o[i] < 2.0 * d[i]);
    let centre: [f64; 3] = if usable {
        std::array::from_fn(|i| o[i] - 1.0)
    } else {
        std::array::from_fn(|i| (d[i] - 1.0) / 2.0)
    };
    let z = DVec3::new(-(spacing[0] as f64), spacing[1] as f64, spacing[2] as f64);
    let linear = DMat3::from_diagonal(z);
    Orientation {
        linear,
        offset: -(linear * DVec3::from_array(centre)),
        source: AffineSource::Assumed,
    }
}

/// Loads an Analyze 7.5 pair given either file; `header_bytes` is the header file's
/// first 348 bytes, already read (and decompressed) by the caller.
pub fn load(
    header_path: &Path,
    image_path: &Path,
    buf: &[u8; 348],
    reading: super::Reading<'_>,
) -> Result<Volume, VolumeError> {
    let super::Reading {
        max_bytes,
        warnings,
        progress,
    } = reading;
    let (h, origin) = parse_header(buf, header_path)?;
    let want = super::FrameRequest {
        frame: 0,
        max_bytes,
    };
    let lay: Layout = nifti::layout(&h, want, header_path)?;
    if lay.frames > 1 {
        warnings.push(format!(
            "Analyze file holds {} frames; showing frame 0",
            lay.frames
        ));
    }
    let (mut r, exact, bound) = nifti::open_maybe_gz(image_path)
        .map_err(|e| super::with_context(e, header_path, "Analyze 7.5 header; its image file"))?;
    let end = lay.vox_offset + lay.frame_bytes;
    if exact.map_or(bound < end, |len| len < end) {
        return Err(VolumeError::Truncated {
            path: image_path.to_owned(),
            what: format!(
                "{} {} voxels (header {})",
                super::fmt_dims(lay.dims),
                lay.ty,
                super::display_path(header_path)
            ),
            expected: end,
            actual: exact.unwrap_or(bound),
        });
    }
    nifti::skip(&mut r, lay.vox_offset, image_path, "vox_offset", 0)?;
    let data = nifti::read_voxels(
        &mut r,
        &lay,
        h.little_endian,
        image_path,
        lay.vox_offset,
        progress,
    )?;
    if exact.is_none() {
        super::gzip::finish_gzip(&mut r, image_path)?;
    }
    let mut spacing = nifti::spacing(&h, warnings);
    let mut orient = orientation(lay.dims, spacing, origin);
    super::fix_spacing(
        &mut spacing,
        &mut orient,
        &["pixdim[1]", "pixdim[2]", "pixdim[3]"],
        warnings,
    );
    warnings.push(
        "Analyze 7.5 stores no orientation: assuming LAS (radiological, x towards the patient's left), as nibabel and SPM read it"
            .into(),
    );
    let scaling = if h.scl_slope.is_finite() && h.scl_slope != 0.0 {
        Scaling {
            slope: h.scl_slope,
            inter: if h.scl_inter.is_finite() {
                h.scl_inter
            } else {
                0.0
            },
        }
    } else {
        Scaling::IDENTITY
    };
    let mut descriptions = Vec::new();
    if !h.descrip.is_empty() {
        descriptions.push(("description".to_owned(), h.descrip.clone()));
    }
    Ok(Volume {
        dims: lay.dims,
        spacing,
        data,
        scaling,
        orientation: orient,
        descriptions,
    })
}
