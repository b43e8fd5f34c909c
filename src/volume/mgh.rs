//! FreeSurfer MGH (`.mgh`) and MGZ (`.mgz`, the same gzip-compressed) volumes.
//!
//! A version-1 header, big-endian: width, height, depth, nframes, type, dof (i32),
//! goodRASflag (i16), spacing `delta` (3 × f32), direction cosines `Mdc` (3 × 3 f32, the
//! x, y, z axis directions one after the other) and `Pxyz_c` (3 × f32, the RAS position
//! of the volume centre). The voxels start at byte 284, x fastest, frame after frame;
//! an optional footer (TR, flip angle, …) follows and is not read.
//!
//! The voxel → RAS affine is nibabel's `MGHHeader.get_affine`: columns `Mdc · delta`,
//! offset `Pxyz_c − (Mdc · delta) · dims / 2`. With goodRASflag = 0, nibabel (and so
//! volao) takes delta = 1, its default coronal Mdc and `Pxyz_c` = 0.

use super::gzip::{MAX_DEFLATE_RATIO, check_holds, finish_gzip, read_all, skip};
use super::nifti::{self, Layout};
use super::orient::{AffineSource, Orientation};
use super::{FrameRequest, Reading, Scaling, Volume, VolumeError, VoxelType, fmt_bytes, fmt_dims};
use glam::{DMat3, DVec3};
use std::io::Read;
use std::path::Path;

/// Where the voxels start.
pub const DATA_OFFSET: u64 = 284;
/// Bytes of the header fields before the padding.
const HEADER_LEN: usize = 90;
/// nibabel's `_set_affine_default`: the axis directions used when goodRASflag is 0.
pub const DEFAULT_MDC: [[f32; 3]; 3] = [[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];

/// An MGH header as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub version: i32,
    /// width, height, depth, nframes.
    pub dims: [i32; 4],
    pub ty: i32,
    pub dof: i32,
    pub good_ras: i16,
    pub delta: [f32; 3],
    /// `mdc[k]` is the RAS direction of voxel axis k (x, y, z).
    pub mdc: [[f32; 3]; 3],
    pub pxyz_c: [f32; 3],
}

impl Header {
    /// Parses the first 90 bytes of an MGH file.
    pub fn parse(b: &[u8; HEADER_LEN]) -> Self {
        let i32_at = |at: usize| i32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        let f32_at = |at: usize| f32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
        let f3 = |at: usize| [f32_at(at), f32_at(at + 4), f32_at(at + 8)];
        Self {
            version: i32_at(0),
            dims: std::array::from_fn(|k| i32_at(4 + 4 * k)),
            ty: i32_at(20),
            dof: i32_at(24),
            good_ras: i16::from_be_bytes([b[28], b[29]]),
            delta: f3(30),
            mdc: [f3(42), f3(54), f3(66)],
            pxyz_c: f3(78),
        }
    }

    /// The bytes of this header, padded to [`DATA_OFFSET`] (for tests and writers).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(DATA_OFFSET as usize);
        b.extend(self.version.to_be_bytes());
        for d in self.dims {
            b.extend(d.to_be_bytes());
        }
        b.extend(self.ty.to_be_bytes());
        b.extend(self.dof.to_be_bytes());
        b.extend(self.good_ras.to_be_bytes());
        let floats = self.delta.iter().chain(self.mdc.iter().flatten());
        for f in floats.chain(self.pxyz_c.iter()) {
            b.extend(f.to_be_bytes());
        }
        b.resize(DATA_OFFSET as usize, 0);
        b
    }

    /// Spacing, axis directions and centre as nibabel uses them: the stored ones, or
    /// its defaults when goodRASflag is 0.
    pub fn geometry(&self) -> ([f32; 3], [[f32; 3]; 3], [f32; 3]) {
        if self.good_ras == 0 {
            ([1.0; 3], DEFAULT_MDC, [0.0; 3])
        } else {
            (self.delta, self.mdc, self.pxyz_c)
        }
    }

    /// nibabel's `MGHHeader.get_affine` (voxel index → RAS mm).
    pub fn affine(&self) -> Orientation {
        let (delta, mdc, c) = self.geometry();
        let col = |k: usize| DVec3::from_array(mdc[k].map(f64::from)) * f64::from(delta[k]);
        let linear = DMat3::from_cols(col(0), col(1), col(2));
        let half = DVec3::from_array(std::array::from_fn(|k| f64::from(self.dims[k]) / 2.0));
        Orientation {
            linear,
            offset: DVec3::from_array(c.map(f64::from)) - linear * half,
            source: if self.good_ras == 0 {
                AffineSource::Assumed
            } else {
                AffineSource::Header
            },
        }
    }
}

/// The voxel type of an MGH type code, or the refusal naming it.
fn voxel_type(code: i32, path: &Path) -> Result<VoxelType, VolumeError> {
    Ok(match code {
        0 => VoxelType::U8,
        1 => VoxelType::I32,
        3 => VoxelType::F32,
        4 => VoxelType::I16,
        10 => VoxelType::U16,
        _ => {
            let name = match code {
                2 => "MRI_LONG",
                5 => "MRI_BITMAP",
                6 => "MRI_TENSOR",
                7 => "MRI_FLOAT_COMPLEX",
                8 => "MRI_DOUBLE_COMPLEX",
                9 => "MRI_RGB",
                _ => "unknown",
            };
            return Err(VolumeError::unsupported(
                path,
                format!(
                    "MGH type {code} ({name}): volao reads UCHAR (0), INT (1), FLOAT (3), SHORT (4) and USHRT (10)"
                ),
            ));
        }
    })
}

/// Checks the header and where frame `want.frame` lies, before anything is allocated.
pub fn layout(h: &Header, want: FrameRequest, path: &Path) -> Result<Layout, VolumeError> {
    if h.version != 1 {
        return Err(VolumeError::invalid(
            path,
            format!(
                "MGH version {} (expected 1): not an MGH file, or a newer one",
                h.version
            ),
        ));
    }
    if let Some(bad) = h.dims.iter().find(|&&d| d < 1) {
        return Err(VolumeError::invalid(
            path,
            format!(
                "MGH width, height, depth, nframes = {:?}: {bad} must be ≥ 1",
                h.dims
            ),
        ));
    }
    let ty = voxel_type(h.ty, path)?;
    let dims = [h.dims[0], h.dims[1], h.dims[2]].map(|d| d as usize);
    let frames = h.dims[3] as u64;
    // Each dimension is below 2³¹, so the frame's bytes fit in u128 and are checked in u64.
    let frame_bytes = dims.iter().fold(ty.size() as u128, |p, &d| p * d as u128);
    let all_frames_fit = frame_bytes * u128::from(frames) < 1 << 62;
    let frame_bytes = u64::try_from(frame_bytes).unwrap_or(u64::MAX);
    if !all_frames_fit && frame_bytes <= want.max_bytes {
        return Err(VolumeError::invalid(
            path,
            format!(
                "MGH header claims {frames} frames of {}: more than any file holds",
                fmt_bytes(frame_bytes)
            ),
        ));
    }
    want.check(path, dims, ty.to_string(), frame_bytes, frames)?;
    Ok(Layout {
        dims,
        ty,
        frame_bytes,
        frames,
        vox_offset: DATA_OFFSET,
    })
}

/// Loads frame `frame` of an `.mgh` or `.mgz` file (gzip is told by its magic bytes).
pub fn load(
    path: &Path,
    frame: usize,
    reading: Reading<'_>,
) -> Result<(Volume, Header), VolumeError> {
    let (r, exact, bound) = nifti::open_maybe_gz(path)?;
    read(r, exact, bound, frame, reading, path)
}

/// Loads an in-memory `.mgh` or `.mgz` (mutation tests); `path` is for messages only.
pub fn load_bytes(
    bytes: &[u8],
    frame: usize,
    max_bytes: u64,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Volume, VolumeError> {
    let len = bytes.len() as u64;
    let (r, exact, bound): (Box<dyn Read + '_>, _, _) = if bytes.starts_with(&[0x1f, 0x8b]) {
        let r = flate2::read::MultiGzDecoder::new(bytes);
        (Box::new(r), None, len.saturating_mul(MAX_DEFLATE_RATIO))
    } else {
        (Box::new(bytes), Some(len), len)
    };
    let reading = Reading {
        max_bytes,
        warnings,
        progress: &mut |_, _| {},
    };
    read(r, exact, bound, frame, reading, path).map(|(v, _)| v)
}

/// Reads header and frame from `r`: `exact` is the plain file's length, `bound` the
/// most bytes it can yield (a gzip stream's deflate bound).
fn read(
    mut r: Box<dyn Read + '_>,
    exact: Option<u64>,
    bound: u64,
    frame: usize,
    reading: Reading<'_>,
    path: &Path,
) -> Result<(Volume, Header), VolumeError> {
    let Reading {
        max_bytes,
        warnings,
        progress,
    } = reading;
    let mut buf = [0u8; HEADER_LEN];
    read_all(&mut r, &mut buf, path, "MGH header", 0)?;
    let h = Header::parse(&buf);
    let lay = layout(&h, FrameRequest { frame, max_bytes }, path)?;
    let start = DATA_OFFSET + frame as u64 * lay.frame_bytes;
    let end = start + lay.frame_bytes;
    let what = format!("{} {} voxels", fmt_dims(lay.dims), lay.ty);
    check_holds(path, what, end, exact, bound)?;
    let consumed = HEADER_LEN as u64;
    skip(
        &mut r,
        start - consumed,
        path,
        "MGH header padding and earlier frames",
        consumed,
    )?;
    let data = nifti::read_voxels(&mut r, &lay, false, path, start, progress)?;
    if exact.is_none() {
        // gzip: read to the end so the CRC32 and ISIZE are checked.
        finish_gzip(&mut r, path)?;
    }
    let (delta, _, _) = h.geometry();
    let mut spacing = delta.map(f32::abs);
    let mut orientation = h.affine();
    if h.good_ras == 0 {
        warnings.push(
            "MGH goodRASflag is 0 (no orientation stored): assuming 1 mm voxels in FreeSurfer's default coronal orientation, as nibabel does"
                .into(),
        );
    } else if !orientation.is_valid() {
        warnings.push(
            "MGH Mdc/Pxyz_c give a singular or non-finite affine; ignoring the orientation".into(),
        );
        orientation = Orientation::from_spacing(spacing);
    }
    super::fix_spacing(
        &mut spacing,
        &mut orientation,
        &["MGH delta[0]", "MGH delta[1]", "MGH delta[2]"],
        warnings,
    );
    let mut descriptions = Vec::new();
    if lay.frames > 1 {
        descriptions.push((
            "frame".to_owned(),
            format!(
                "{frame} of {} (frames count from 0; choose with --frame)",
                lay.frames
            ),
        ));
    }
    Ok((
        Volume {
            dims: lay.dims,
            spacing,
            data,
            scaling: Scaling::IDENTITY,
            orientation,
            descriptions,
        },
        h,
    ))
}
