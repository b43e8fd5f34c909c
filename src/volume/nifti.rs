//! NIfTI-1 and NIfTI-2: `.nii`, `.nii.gz`, `.hdr`/`.img` pairs, either byte order.
//!
//! NIfTI-1 headers are parsed by the `nifti` crate. It knows neither NIfTI-2 nor a way to
//! stream voxels into a caller's buffer, and its writer always resets `scl_slope`, so the
//! NIfTI-2 header, the voxel reading and the writer are ours. Voxels are read straight
//! into their final typed buffer and byte-swapped in place: loading peaks at one payload.

use super::gzip::check_holds;
pub use super::gzip::{MAX_DEFLATE_RATIO, read_all, skip};
use super::orient::{AffineSource, Orientation};
use super::{
    FrameRequest, Scaling, Volume, VolumeError, VoxelData, VoxelType, fmt_bytes, fmt_dims,
};
use glam::{DMat3, DVec3};
use std::io::Read;
use std::path::{Path, PathBuf};

mod write;
pub use write::{encode_header, save};

/// The header fields volao uses, from either NIfTI version.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub version: u8,
    pub little_endian: bool,
    /// `dim[0..8]`: `dim[0]` is the number of dimensions.
    pub dim: [i64; 8],
    pub datatype: i16,
    pub pixdim: [f64; 8],
    pub vox_offset: f64,
    pub scl_slope: f64,
    pub scl_inter: f64,
    pub qform_code: i32,
    pub sform_code: i32,
    pub quatern: [f64; 3],
    pub qoffset: [f64; 3],
    pub srow: [[f64; 4]; 3],
    pub descrip: String,
    pub intent_code: i32,
    /// `n+1`/`n+2` (single file) rather than `ni1`/`ni2` (header/image pair).
    pub single_file: bool,
}

impl Header {
    /// Size of the fixed header in bytes (348 or 540).
    pub fn size(&self) -> u64 {
        if self.version == 2 { 540 } else { 348 }
    }
}

/// Where the voxels of one NIfTI dataset live.
#[derive(Debug, Clone)]
pub struct NiftiPaths {
    pub header: PathBuf,
    pub image: PathBuf,
}

/// Whether a path names a NIfTI file by its extension.
pub fn is_nifti_path(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    [".nii", ".nii.gz", ".hdr", ".hdr.gz", ".img", ".img.gz"]
        .iter()
        .any(|e| name.ends_with(e))
}

/// Finds the header and image files of a dataset given either of them.
pub fn resolve_paths(path: &Path) -> NiftiPaths {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let lower = name.to_ascii_lowercase();
    let swap = |from: &str, to: &str| -> PathBuf {
        let stem = &name[..name.len() - from.len()];
        // Keep the case style of the extension the user gave.
        let to = if name[name.len() - from.len()..]
            .chars()
            .any(|c| c.is_ascii_uppercase())
        {
            to.to_ascii_uppercase()
        } else {
            to.to_owned()
        };
        let candidate = path.with_file_name(format!("{stem}{to}"));
        // `x.img.gz` may pair with a plain `x.hdr`, and vice versa.
        if !candidate.exists() {
            for alt in [to.trim_end_matches(".gz").to_owned(), format!("{to}.gz")] {
                let c = path.with_file_name(format!("{stem}{alt}"));
                if c.exists() {
                    return c;
                }
            }
        }
        candidate
    };
    for (h, i) in [(".hdr.gz", ".img.gz"), (".hdr", ".img")] {
        if lower.ends_with(h) {
            return NiftiPaths {
                header: path.to_owned(),
                image: swap(h, i),
            };
        }
        if lower.ends_with(i) {
            return NiftiPaths {
                header: swap(i, h),
                image: path.to_owned(),
            };
        }
    }
    NiftiPaths {
        header: path.to_owned(),
        image: path.to_owned(),
    }
}

/// Reads a NIfTI header from the start of `r` (already decompressed).
pub fn read_header(r: &mut impl Read, path: &Path) -> Result<Header, VolumeError> {
    let mut first = [0u8; 4];
    read_all(r, &mut first, path, "the NIfTI header", 0)?;
    let le = i32::from_le_bytes(first);
    let be = i32::from_be_bytes(first);
    match (le, be) {
        (348, _) | (_, 348) => {
            let mut buf = [0u8; 348];
            buf[..4].copy_from_slice(&first);
            read_all(r, &mut buf[4..], path, "the NIfTI-1 header", 4)?;
            parse_nifti1(&buf, path)
        }
        (540, _) | (_, 540) => {
            let mut buf = [0u8; 540];
            buf[..4].copy_from_slice(&first);
            read_all(r, &mut buf[4..], path, "the NIfTI-2 header", 4)?;
            parse_nifti2(&buf, le == 540, path)
        }
        _ => Err(VolumeError::invalid(
            path,
            format!(
                "not a NIfTI file (the first 4 bytes {first:02x?} should hold the header size 348 or 540)"
            ),
        )),
    }
}

fn parse_nifti1(buf: &[u8; 348], path: &Path) -> Result<Header, VolumeError> {
    let h = nifti::NiftiHeader::from_reader(&buf[..]).map_err(|e| {
        VolumeError::invalid(
            path,
            format!(
                "not a valid NIfTI-1 header ({e}); magic is {:?}",
                &buf[344..348]
            ),
        )
    })?;
    let text = |b: &[u8]| {
        let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
        String::from_utf8_lossy(&b[..end]).trim().to_owned()
    };
    let f = |x: f32| x as f64;
    let row = |r: [f32; 4]| r.map(f);
    Ok(Header {
        version: 1,
        little_endian: h.endianness == nifti::Endianness::Little,
        // nifti-rs reads dim as u16; NIfTI-1 stores i16, so reinterpret to see negatives.
        dim: h.dim.map(|d| d as i16 as i64),
        datatype: h.datatype,
        pixdim: h.pixdim.map(f),
        vox_offset: f(h.vox_offset),
        scl_slope: f(h.scl_slope),
        scl_inter: f(h.scl_inter),
        qform_code: h.qform_code as i32,
        sform_code: h.sform_code as i32,
        quatern: [f(h.quatern_b), f(h.quatern_c), f(h.quatern_d)],
        qoffset: [f(h.quatern_x), f(h.quatern_y), f(h.quatern_z)],
        srow: [row(h.srow_x), row(h.srow_y), row(h.srow_z)],
        descrip: text(&h.descrip),
        intent_code: h.intent_code as i32,
        single_file: &h.magic == b"n+1\0",
    })
}

/// NIfTI-2 (540-byte header with 64-bit fields), which the `nifti` crate does not read.
fn parse_nifti2(buf: &[u8; 540], little_endian: bool, path: &Path) -> Result<Header, VolumeError> {
    let magic = &buf[4..12];
    let single_file = match magic {
        b"n+2\0\r\n\x1a\n" => true,
        b"ni2\0\r\n\x1a\n" => false,
        _ => {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "header size says NIfTI-2 but the magic is {magic:02x?}, not \"n+2\" or \"ni2\""
                ),
            ));
        }
    };
    let f = super::fields::Fields::new(buf, little_endian);
    Ok(Header {
        version: 2,
        little_endian,
        dim: std::array::from_fn(|k| f.i64(16 + 8 * k)),
        datatype: f.i16(12),
        pixdim: std::array::from_fn(|k| f.f64(104 + 8 * k)),
        vox_offset: f.i64(168) as f64,
        scl_slope: f.f64(176),
        scl_inter: f.f64(184),
        qform_code: f.i32(344),
        sform_code: f.i32(348),
        quatern: [f.f64(352), f.f64(360), f.f64(368)],
        qoffset: [f.f64(376), f.f64(384), f.f64(392)],
        srow: std::array::from_fn(|r| std::array::from_fn(|c| f.f64(400 + 32 * r + 8 * c))),
        descrip: f.text(240, 80),
        intent_code: f.i32(504),
        single_file,
    })
}

/// NIfTI datatype code → voxel type.
pub fn voxel_type(code: i16) -> Option<VoxelType> {
    Some(match code {
        2 => VoxelType::U8,
        4 => VoxelType::I16,
        8 => VoxelType::I32,
        16 => VoxelType::F32,
        64 => VoxelType::F64,
        256 => VoxelType::I8,
        512 => VoxelType::U16,
        768 => VoxelType::U32,
        _ => return None,
    })
}

/// Voxel type → NIfTI datatype code.
pub fn datatype_code(ty: VoxelType) -> i16 {
    match ty {
        VoxelType::U8 => 2,
        VoxelType::I16 => 4,
        VoxelType::I32 => 8,
        VoxelType::F32 => 16,
        VoxelType::F64 => 64,
        VoxelType::I8 => 256,
        VoxelType::U16 => 512,
        VoxelType::U32 => 768,
    }
}

fn datatype_name(code: i16) -> String {
    match code {
        1 => "binary (1 bit)".into(),
        32 => "complex64".into(),
        128 => "RGB24".into(),
        1024 => "int64".into(),
        1280 => "uint64".into(),
        1536 => "float128".into(),
        1792 => "complex128".into(),
        2048 => "complex256".into(),
        2304 => "RGBA32".into(),
        c => format!("code {c}"),
    }
}

/// What a validated header says about the voxels to read.
#[derive(Debug, Clone)]
pub struct Layout {
    pub dims: [usize; 3],
    pub ty: VoxelType,
    /// Bytes of one 3-D frame.
    pub frame_bytes: u64,
    /// Number of 3-D frames (product of `dim[4..]`).
    pub frames: u64,
    /// Byte offset of the voxels in the image file (0 for most .img files).
    pub vox_offset: u64,
}

/// Checks every header field the reader relies on, before anything is allocated.
pub fn layout(h: &Header, want: FrameRequest, path: &Path) -> Result<Layout, VolumeError> {
    let ndim = h.dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(VolumeError::invalid(
            path,
            format!("dim[0] = {ndim}: the number of dimensions must be 1 to 7"),
        ));
    }
    let ndim = ndim as usize;
    let mut dim = [1i64; 8];
    dim[1..=ndim].copy_from_slice(&h.dim[1..=ndim]);
    if let Some(bad) = dim[1..=ndim].iter().find(|&&d| d < 1) {
        return Err(VolumeError::invalid(
            path,
            format!(
                "dimension {bad} in dim[1..{}] = {:?} must be ≥ 1",
                ndim + 1,
                &h.dim[1..=ndim]
            ),
        ));
    }
    if dim[5] > 1 {
        return Err(VolumeError::unsupported(
            path,
            format!(
                "5-D NIfTI with {} components per voxel (intent {}; e.g. vectors or displacement fields): volao renders scalar volumes only",
                dim[5], h.intent_code
            ),
        ));
    }
    let ty = voxel_type(h.datatype).ok_or_else(|| {
        VolumeError::unsupported(
            path,
            format!(
                "NIfTI datatype {} is not supported (supported: u8, i8, u16, i16, u32, i32, f32, f64)",
                datatype_name(h.datatype)
            ),
        )
    })?;
    let to_usize = |d: i64| usize::try_from(d).ok();
    let dims = [dim[1], dim[2], dim[3]].map(to_usize);
    let [Some(nx), Some(ny), Some(nz)] = dims else {
        return Err(VolumeError::invalid(
            path,
            "dimensions do not fit in memory addresses",
        ));
    };
    let dims = [nx, ny, nz];
    let frames = dim[4..8]
        .iter()
        .try_fold(1u64, |acc, &d| acc.checked_mul(d as u64));
    let frame_bytes = (nx as u64)
        .checked_mul(ny as u64)
        .and_then(|n| n.checked_mul(nz as u64))
        .and_then(|n| n.checked_mul(ty.size() as u64));
    let (Some(frames), Some(frame_bytes)) = (frames, frame_bytes) else {
        return Err(VolumeError::invalid(
            path,
            format!("dimensions {:?} overflow", &h.dim[1..=ndim]),
        ));
    };
    want.check(path, dims, ty.name().to_owned(), frame_bytes, frames)?;
    let vo = h.vox_offset;
    if !vo.is_finite() || vo < 0.0 || vo.fract() != 0.0 {
        return Err(VolumeError::invalid(
            path,
            format!("vox_offset {vo} is not a whole, non-negative byte offset"),
        ));
    }
    let vox_offset = vo as u64;
    // All later offset arithmetic (start of any frame + its size) must fit in u64.
    if frames
        .checked_mul(frame_bytes)
        .and_then(|b| b.checked_add(vox_offset))
        .is_none_or(|end| end > 1 << 62)
    {
        return Err(VolumeError::invalid(
            path,
            format!("vox_offset {vox_offset} and {frames} frames point beyond any file"),
        ));
    }
    if h.single_file && vox_offset < h.size() {
        return Err(VolumeError::invalid(
            path,
            format!(
                "vox_offset {vox_offset} points inside the {}-byte header",
                h.size()
            ),
        ));
    }
    Ok(Layout {
        dims,
        ty,
        frame_bytes,
        frames,
        vox_offset,
    })
}

/// Voxel spacing from `pixdim[1..4]`; unusable values become 1 mm with a warning.
pub fn spacing(h: &Header, warnings: &mut Vec<String>) -> [f32; 3] {
    std::array::from_fn(|k| {
        // Check in f32, the type we keep: a huge NIfTI-2 f64 would become infinite.
        let s = h.pixdim[k + 1] as f32;
        let axis = ["x", "y", "z"][k];
        if s.is_finite() && s > 0.0 {
            s
        } else if s.is_finite() && s < 0.0 {
            warnings.push(format!(
                "pixdim[{}] = {s} is negative; using {} mm (orientation comes from qform/sform)",
                k + 1,
                -s
            ));
            -s
        } else {
            warnings.push(format!(
                "{axis} spacing pixdim[{}] = {s} is not usable; using 1 mm",
                k + 1
            ));
            1.0
        }
    })
}

/// Orientation by NIfTI's rules: sform if `sform_code > 0`, else qform if
/// `qform_code > 0`, else the spacing alone ("method 1", taken as RAS).
pub fn orientation(h: &Header, spacing: [f32; 3], warnings: &mut Vec<String>) -> Orientation {
    if h.sform_code > 0 {
        let o = Orientation::from_rows(h.srow, AffineSource::Sform);
        if o.is_valid() {
            return o;
        }
        warnings.push("sform is singular or not finite; ignoring it".into());
    }
    if h.qform_code > 0 {
        let o = qform_orientation(h, spacing);
        if o.is_valid() {
            return o;
        }
        warnings.push("qform is not finite; ignoring it".into());
    }
    Orientation::from_spacing(spacing)
}

/// The qform quaternion → rotation, with `qfac = pixdim[0]` flipping z (nifti1_io's
/// `quatern_to_mat44`).
fn qform_orientation(h: &Header, spacing: [f32; 3]) -> Orientation {
    let [mut b, mut c, mut d] = h.quatern;
    let mut a2 = 1.0 - (b * b + c * c + d * d);
    if a2 < 1e-7 {
        // Not a unit quaternion: normalise (b, c, d) and take a 180° rotation.
        let n = (b * b + c * c + d * d).sqrt();
        if n > 0.0 {
            (b, c, d) = (b / n, c / n, d / n);
        }
        a2 = 0.0;
    }
    let a = a2.sqrt();
    let r = DMat3::from_cols(
        DVec3::new(
            a * a + b * b - c * c - d * d,
            2.0 * (b * c + a * d),
            2.0 * (b * d - a * c),
        ),
        DVec3::new(
            2.0 * (b * c - a * d),
            a * a + c * c - b * b - d * d,
            2.0 * (c * d + a * b),
        ),
        DVec3::new(
            2.0 * (b * d + a * c),
            2.0 * (c * d - a * b),
            a * a + d * d - c * c - b * b,
        ),
    );
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let s = DVec3::new(
        spacing[0] as f64,
        spacing[1] as f64,
        spacing[2] as f64 * qfac,
    );
    Orientation {
        linear: r * DMat3::from_diagonal(s),
        offset: DVec3::from_array(h.qoffset),
        source: AffineSource::Qform,
    }
}

/// Stored → physical map; `scl_slope = 0` (or not finite) means "no scaling".
pub fn scaling(h: &Header) -> Scaling {
    if h.scl_slope == 0.0 || !h.scl_slope.is_finite() {
        return Scaling::IDENTITY;
    }
    let inter = if h.scl_inter.is_finite() {
        h.scl_inter
    } else {
        0.0
    };
    Scaling {
        slope: h.scl_slope,
        inter,
    }
}

/// Builds the volume once its voxels are read.
pub fn assemble(h: &Header, lay: &Layout, data: VoxelData, warnings: &mut Vec<String>) -> Volume {
    let mut spacing = spacing(h, warnings);
    let mut orientation = orientation(h, spacing, warnings);
    super::fix_spacing(
        &mut spacing,
        &mut orientation,
        &["pixdim[1]", "pixdim[2]", "pixdim[3]"],
        warnings,
    );
    if !h.scl_slope.is_finite() {
        warnings.push(format!(
            "scl_slope = {} is not finite; showing stored values unscaled",
            h.scl_slope
        ));
    } else if h.scl_slope != 0.0 && !h.scl_inter.is_finite() {
        warnings.push(format!(
            "scl_inter = {} is not finite; using 0",
            h.scl_inter
        ));
    }
    let mut descriptions = Vec::new();
    if !h.descrip.is_empty() {
        descriptions.push(("description".to_owned(), h.descrip.clone()));
    }
    Volume {
        dims: lay.dims,
        spacing,
        data,
        scaling: scaling(h),
        orientation,
        descriptions,
    }
}

/// Reads one frame of voxels into a new typed buffer, reporting progress in bytes.
pub fn read_voxels(
    r: &mut impl Read,
    lay: &Layout,
    little_endian: bool,
    path: &Path,
    consumed: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<VoxelData, VolumeError> {
    let n = lay.dims[0] * lay.dims[1] * lay.dims[2];
    let mut data = VoxelData::try_zeroed(lay.ty, n).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "cannot allocate {} for the voxels",
                fmt_bytes(lay.frame_bytes)
            ),
        )
    })?;
    let what = format!("{} {} voxels", fmt_dims(lay.dims), lay.ty);
    let bytes = data.as_bytes_mut();
    let total = bytes.len() as u64;
    const CHUNK: usize = 4 << 20;
    let mut done = 0usize;
    for chunk in bytes.chunks_mut(CHUNK) {
        read_all(r, chunk, path, &what, consumed + done as u64)
            .map_err(|e| with_expected(e, consumed + total))?;
        done += chunk.len();
        progress(done as u64, total);
    }
    data.fix_endianness(little_endian);
    Ok(data)
}

/// A truncation inside the voxel block reports the size the whole block needs.
fn with_expected(e: VolumeError, expected: u64) -> VolumeError {
    match e {
        VolumeError::Truncated {
            path, what, actual, ..
        } => VolumeError::Truncated {
            path,
            what,
            expected,
            actual,
        },
        e => e,
    }
}

/// An opened data file: the (decompressing) reader, its exact length when plain, and an
/// upper bound on how many bytes it can yield.
pub type Opened = (Box<dyn Read>, Option<u64>, u64);

/// A stream that may be gzip-compressed (detected by its magic bytes, not the name).
pub fn open_maybe_gz(path: &Path) -> Result<Opened, VolumeError> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
    let head = std::io::BufRead::fill_buf(&mut reader).map_err(|e| VolumeError::io(path, e))?;
    let gz = head.starts_with(&[0x1f, 0x8b]);
    if gz {
        // Decompressed size is unknown but bounded by the deflate ratio.
        Ok((
            Box::new(flate2::read::MultiGzDecoder::new(reader)),
            None,
            len.saturating_mul(MAX_DEFLATE_RATIO),
        ))
    } else {
        Ok((Box::new(reader), Some(len), len))
    }
}

/// Loads frame `frame` of a NIfTI dataset from disk.
pub fn load(
    path: &Path,
    frame: usize,
    reading: super::Reading<'_>,
) -> Result<(Volume, Header), VolumeError> {
    let super::Reading {
        max_bytes,
        warnings,
        progress,
    } = reading;
    let paths = resolve_paths(path);
    let (mut hr, header_len, header_bound) = open_maybe_gz(&paths.header)?;
    let h = read_header(&mut hr, &paths.header)?;
    let lay = layout(&h, FrameRequest { frame, max_bytes }, &paths.header)?;
    let start = lay.vox_offset + frame as u64 * lay.frame_bytes;
    let end = start + lay.frame_bytes;
    let pair = paths.image != paths.header;
    if !h.single_file && !pair {
        warnings.push("header says it belongs to a .hdr/.img pair (magic ni1/ni2); reading voxels from this file".into());
    }
    let (mut r, consumed, exact_len, bound) = if pair {
        let (r, exact, bound) = open_maybe_gz(&paths.image)
            .map_err(|e| super::with_context(e, &paths.header, "NIfTI header; its image file"))?;
        (r, 0, exact, bound)
    } else {
        (hr, h.size(), header_len, header_bound)
    };
    let data_path = if pair { &paths.image } else { &paths.header };
    let what = format!("{} {} voxels", fmt_dims(lay.dims), lay.ty);
    // Refuse impossible sizes before allocating: exact for plain files, bounded for gzip.
    check_holds(data_path, what, end, exact_len, bound)?;
    let gap = start.checked_sub(consumed).ok_or_else(|| {
        VolumeError::invalid(
            data_path,
            format!("vox_offset {} points inside the header", lay.vox_offset),
        )
    })?;
    skip(
        &mut r,
        gap,
        data_path,
        "header extensions and earlier frames",
        consumed,
    )?;
    let data = read_voxels(&mut r, &lay, h.little_endian, data_path, start, progress)?;
    if exact_len.is_none() {
        // gzip: read to the end so the CRC32 and ISIZE of every member are checked.
        super::gzip::finish_gzip(&mut r, data_path)?;
    }
    let volume = assemble(&h, &lay, data, warnings);
    Ok((volume, h))
}

/// Parses a whole single-file NIfTI (`.nii` or gzip-compressed) held in memory.
/// Used by fuzzing and mutation tests; the file path is only used in messages.
pub fn load_bytes(
    bytes: &[u8],
    frame: usize,
    max_bytes: u64,
    path: &Path,
) -> Result<Volume, VolumeError> {
    let mut warnings = Vec::new();
    let gz = bytes.starts_with(&[0x1f, 0x8b]);
    let bound = if gz {
        (bytes.len() as u64).saturating_mul(MAX_DEFLATE_RATIO)
    } else {
        bytes.len() as u64
    };
    let mut r: Box<dyn Read + '_> = if gz {
        Box::new(flate2::read::MultiGzDecoder::new(bytes))
    } else {
        Box::new(bytes)
    };
    let h = read_header(&mut r, path)?;
    let want = FrameRequest {
        frame,
        max_bytes: max_bytes.min(bound),
    };
    let lay = layout(&h, want, path)?;
    let start = lay.vox_offset + frame as u64 * lay.frame_bytes;
    if start + lay.frame_bytes > bound {
        return Err(VolumeError::Truncated {
            path: path.to_owned(),
            what: "voxels".into(),
            expected: start + lay.frame_bytes,
            actual: bound,
        });
    }
    let gap = start.checked_sub(h.size()).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!("vox_offset {} points inside the header", lay.vox_offset),
        )
    })?;
    skip(
        &mut r,
        gap,
        path,
        "header extensions and earlier frames",
        h.size(),
    )?;
    let data = read_voxels(&mut r, &lay, h.little_endian, path, start, &mut |_, _| {})?;
    if gz {
        super::gzip::finish_gzip(&mut r, path)?;
    }
    Ok(assemble(&h, &lay, data, &mut warnings))
}
