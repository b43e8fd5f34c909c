//! NRRD (teem, 3D Slicer): `.nrrd` with the header attached, `.nhdr` with the voxels in
//! one or more detached files (`data file:`, `LIST`, or a `%d` pattern).
//!
//! Encodings raw, gzip, ascii/text and hex; types int8 … double; either byte order.
//! `space`/`space directions`/`space origin` give the voxel-to-world affine (oblique
//! directions are kept), `spacings` the spacing when there is no space. Axes of size 1
//! are dropped; a slowest axis beyond the three spatial ones is a frame axis (`--frame`),
//! any other non-spatial axis of size ≥ 2 (colour, vector, list) is refused.

use crate::volume::gzip::{MAX_DEFLATE_RATIO, finish_gzip, read_all, skip};
use crate::volume::orient::{AffineSource, Orientation};
use crate::volume::{
    FrameRequest, Volume, VolumeError, VoxelData, VoxelType, fmt_bytes, fmt_dims, short_name,
    with_voxels,
};
use glam::{DMat3, DVec3};
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};

mod header;

use header::*;
pub use header::{Encoding, Header, Layout, Space, parse_header};

/// Chooses x, y, z (and the frame axis) from the header axes.
pub fn layout(h: &Header, want: FrameRequest, path: &Path) -> Result<Layout, VolumeError> {
    let kind = |a: usize| h.kinds.get(a).map(|k| k.to_ascii_lowercase());
    let is_domain = |a: usize| {
        kind(a).is_none_or(|k| DOMAIN_KINDS.contains(&k.as_str()) || k == "none" || k == "???")
    };
    // Axes that matter: size ≥ 2.
    let axes: Vec<usize> = (0..h.sizes.len()).filter(|&a| h.sizes[a] > 1).collect();
    if let Some(&a) = axes.iter().find(|&&a| !is_domain(a)) {
        return Err(VolumeError::unsupported(
            path,
            format!(
                "axis {a} has kind {} and size {}: {} values per voxel (colour, vector or list) — volao renders scalar volumes only",
                h.kinds.get(a).map(String::as_str).unwrap_or_default(),
                h.sizes[a],
                h.sizes[a]
            ),
        ));
    }
    if h.kinds.is_empty()
        && h.directions.is_empty()
        && axes.len() == 3
        && axes[0] == 0
        && (2..=4).contains(&h.sizes[0])
        && h.sizes[1] >= 16 * h.sizes[0]
    {
        return Err(VolumeError::unsupported(
            path,
            format!(
                "sizes {:?} with no kinds: the fastest axis of size {} looks like {} components per voxel (RGB?) — volao renders scalar volumes only; add \"kinds: domain domain domain\" if it really is a volume",
                h.sizes, h.sizes[0], h.sizes[0]
            ),
        ));
    }
    let mut spatial: Vec<usize> = axes
        .iter()
        .copied()
        .filter(|&a| h.directions.get(a).is_none_or(|d| d.is_some()))
        .collect();
    // Without space directions, a 4th axis is the frame axis (as in 4-D NIfTI).
    if h.directions.is_empty() && spatial.len() == 4 {
        spatial.pop();
    }
    let extra: Vec<usize> = axes
        .iter()
        .copied()
        .filter(|a| !spatial.contains(a))
        .collect();
    if spatial.len() > 3 {
        return Err(VolumeError::unsupported(
            path,
            format!(
                "{} axes of size ≥ 2 (sizes {:?}): volao renders 3-D volumes (a 4th, slowest axis is read as frames when its space direction is none)",
                spatial.len(),
                h.sizes
            ),
        ));
    }
    let frame_axis = match extra.as_slice() {
        [] => None,
        [a] if *a == h.sizes.len() - 1 || h.sizes[a + 1..].iter().all(|&s| s == 1) => Some(*a),
        _ => {
            return Err(VolumeError::unsupported(
                path,
                format!(
                    "non-spatial axes {extra:?} (sizes {:?}): only one, the slowest, can be read (as frames)",
                    h.sizes
                ),
            ));
        }
    };
    let mut ax = [None; 3];
    let mut dims = [1usize; 3];
    for (i, &a) in spatial.iter().enumerate() {
        ax[i] = Some(a);
        dims[i] = h.sizes[a];
    }
    let frames = frame_axis.map_or(1, |a| h.sizes[a]);
    let frame_bytes = dims
        .iter()
        .try_fold(h.ty.size() as u64, |acc, &d| acc.checked_mul(d as u64))
        .filter(|b| b.checked_mul(frames as u64).is_some_and(|t| t < 1 << 62))
        .ok_or_else(|| invalid(path, format!("sizes {:?} overflow", h.sizes)))?;
    want.check(path, dims, h.ty.name().into(), frame_bytes, frames as u64)?;
    Ok(Layout {
        dims,
        axes: ax,
        frames,
        frame_bytes,
    })
}

/// Spacing and affine from the header, with warnings for what had to be assumed.
pub fn geometry(
    h: &Header,
    lay: &Layout,
    path: &Path,
    warnings: &mut Vec<String>,
) -> ([f32; 3], Orientation) {
    let _ = path;
    if let Some((space, name)) = &h.space {
        let mut cols = [DVec3::ZERO; 3];
        let mut ok = true;
        for (col, axis) in cols.iter_mut().zip(lay.axes) {
            match axis.and_then(|a| h.directions.get(a).copied().flatten()) {
                Some(d) => *col = DVec3::from_array(d),
                None => ok = axis.is_none() && ok,
            }
        }
        // A missing axis (2-D image): unit step along the remaining orthogonal direction.
        for i in 0..3 {
            if cols[i] == DVec3::ZERO {
                let others: Vec<DVec3> = (0..3).filter(|&j| j != i).map(|j| cols[j]).collect();
                let n = others[0].cross(others[1]);
                cols[i] = if n.length() > 0.0 {
                    n.normalize()
                } else {
                    DVec3::AXES[i]
                };
            }
        }
        let flip = match space {
            Space::Ras | Space::Other => DVec3::new(1.0, 1.0, 1.0),
            Space::Las => DVec3::new(-1.0, 1.0, 1.0),
            Space::Lps => DVec3::new(-1.0, -1.0, 1.0),
        };
        if *space == Space::Other {
            warnings.push(format!(
                "NRRD space {name} has no anatomical meaning; taking its axes as RAS"
            ));
        }
        let origin = DVec3::from_array(h.origin.unwrap_or([0.0; 3])) * flip;
        let linear = DMat3::from_cols(cols[0] * flip, cols[1] * flip, cols[2] * flip);
        let mut spacing: [f32; 3] = std::array::from_fn(|i| linear.col(i).length() as f32);
        let o = Orientation {
            linear,
            offset: origin,
            source: AffineSource::Header,
        };
        let fields = [
            "space directions (x)",
            "space directions (y)",
            "space directions (z)",
        ];
        let mut o = o;
        super::fix_spacing(&mut spacing, &mut o, &fields, warnings);
        if ok && o.is_valid() {
            return (spacing, o);
        }
        warnings.push("space directions are degenerate; using the spacing alone".into());
        return (spacing, Orientation::from_spacing(spacing));
    }
    let mut spacing = [1.0f32; 3];
    for (sp, axis) in spacing.iter_mut().zip(lay.axes) {
        if let Some(s) = axis.and_then(|a| h.spacings.get(a)) {
            *sp = s.abs() as f32;
        }
    }
    let fields = ["spacings (x)", "spacings (y)", "spacings (z)"];
    let mut o = Orientation::from_spacing(spacing);
    if h.spacings.is_empty() {
        warnings.push("NRRD header gives neither space directions nor spacings; using 1 mm".into());
    }
    super::fix_spacing(&mut spacing, &mut o, &fields, warnings);
    (spacing, Orientation::from_spacing(spacing))
}

/// Reads the header of `path` (up to the blank line that ends it, or the end of a
/// detached header); `header_len` is where attached voxels start.
pub fn read_header_file(path: &Path) -> Result<Header, VolumeError> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut r = std::io::BufReader::new(file).take(MAX_HEADER);
    let mut text = String::new();
    let mut len = 0u64;
    loop {
        let mut line = Vec::new();
        let n = r
            .read_until(b'\n', &mut line)
            .map_err(|e| VolumeError::io(path, e))?;
        if n == 0 {
            break;
        }
        len += n as u64;
        let s = String::from_utf8_lossy(&line);
        if s.trim_end_matches(['\n', '\r']).is_empty() {
            break;
        }
        text.push_str(&s);
        if !text.starts_with("NRRD000") {
            break; // not NRRD: parse_header says so without reading further
        }
    }
    if len >= MAX_HEADER {
        return Err(invalid(
            path,
            format!(
                "no blank line ends the header in the first {}",
                fmt_bytes(MAX_HEADER)
            ),
        ));
    }
    let mut h = parse_header(&text, path)?;
    h.header_len = len;
    Ok(h)
}

/// The files that hold the voxels, in order; the header file itself when attached.
pub fn data_paths(h: &Header, header_path: &Path) -> Vec<PathBuf> {
    if h.data_files.is_empty() {
        return vec![header_path.to_owned()];
    }
    let dir = header_path.parent().unwrap_or(Path::new(""));
    h.data_files
        .iter()
        .map(|f| {
            let p = Path::new(f);
            if p.is_absolute() {
                p.to_owned()
            } else {
                dir.join(p)
            }
        })
        .collect()
}

/// Opens one data file with its skips applied: the decoded byte stream and an upper
/// bound on how many bytes it yields.
/// The text of every data file of an ASCII or hex NRRD, one after another (each ended
/// by a newline); refused beyond what `max_bytes` of voxels could be written as.
fn read_text_parts(
    h: &Header,
    parts: &[PathBuf],
    offset: u64,
    per_part: u64,
    max_bytes: u64,
) -> Result<Vec<u8>, VolumeError> {
    let mut text = Vec::new();
    for p in parts {
        let (r, bound) = open_part(h, p, offset, per_part)?;
        if bound > max_bytes.saturating_mul(24) {
            return Err(invalid(
                p,
                "text data larger than any volume that fits in memory",
            ));
        }
        r.take(bound)
            .read_to_end(&mut text)
            .map_err(|e| VolumeError::io(p, e))?;
        text.push(b'\n');
    }
    Ok(text)
}

fn open_part(
    h: &Header,
    path: &Path,
    attached_offset: u64,
    bytes_needed: u64,
) -> Result<(Box<dyn Read>, u64), VolumeError> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let mut r = std::io::BufReader::with_capacity(1 << 16, file);
    let mut consumed = attached_offset;
    skip(&mut r, attached_offset, path, "the NRRD header", 0)?;
    for _ in 0..h.line_skip {
        let mut line = Vec::new();
        let n = (&mut r)
            .take(1 << 20)
            .read_until(b'\n', &mut line)
            .map_err(|e| VolumeError::io(path, e))?;
        if n == 0 {
            return Err(VolumeError::Truncated {
                path: path.to_owned(),
                what: format!("line skip {}", h.line_skip),
                expected: consumed + 1,
                actual: consumed,
            });
        }
        consumed += n as u64;
    }
    let remaining = len.saturating_sub(consumed);
    if h.encoding == Encoding::Raw {
        let skip_n = if h.byte_skip == -1 {
            remaining
                .checked_sub(bytes_needed)
                .ok_or_else(|| VolumeError::Truncated {
                    path: path.to_owned(),
                    what: "voxels (byte skip -1)".into(),
                    expected: bytes_needed,
                    actual: remaining,
                })?
        } else {
            h.byte_skip as u64
        };
        skip(&mut r, skip_n, path, "byte skip", consumed)?;
        return Ok((Box::new(r), remaining.saturating_sub(skip_n)));
    }
    let mut d: Box<dyn Read> = match h.encoding {
        Encoding::Gzip => Box::new(flate2::read::MultiGzDecoder::new(r)),
        _ => Box::new(r),
    };
    let bound = if h.encoding == Encoding::Gzip {
        remaining.saturating_mul(MAX_DEFLATE_RATIO)
    } else {
        remaining
    };
    skip(&mut d, h.byte_skip as u64, path, "byte skip", 0)?;
    Ok((d, bound.saturating_sub(h.byte_skip as u64)))
}

/// Loads frame `frame` of a NRRD file (`.nrrd` or `.nhdr`).
pub fn load(
    path: &Path,
    frame: usize,
    reading: super::Reading<'_>,
) -> Result<(Volume, PathBuf), VolumeError> {
    let max_bytes = reading.max_bytes;
    let h = read_header_file(path)?;
    let lay = layout(&h, FrameRequest { frame, max_bytes }, path)?;
    let parts = data_paths(&h, path);
    let attached = h.data_files.is_empty();
    let total = lay.frame_bytes * lay.frames as u64;
    if !total.is_multiple_of(parts.len() as u64) {
        return Err(invalid(
            path,
            format!(
                "{} bytes of voxels cannot be split evenly over {} data files",
                total,
                parts.len()
            ),
        ));
    }
    let per_part = total / parts.len() as u64;
    let n = lay.dims.iter().product::<usize>();
    let mut data = VoxelData::try_zeroed(h.ty, n).ok_or_else(|| {
        invalid(
            path,
            format!(
                "cannot allocate {} for the voxels",
                fmt_bytes(lay.frame_bytes)
            ),
        )
    })?;
    let start = frame as u64 * lay.frame_bytes;
    let end = start + lay.frame_bytes;
    let what = format!("{} {} voxels", fmt_dims(lay.dims), h.ty);
    let mut last_path = path.to_owned();
    match h.encoding {
        Encoding::Raw | Encoding::Gzip => {
            let out = data.as_bytes_mut();
            for (k, p) in parts.iter().enumerate() {
                let (p0, p1) = (k as u64 * per_part, (k as u64 + 1) * per_part);
                if p1 <= start || p0 >= end {
                    continue;
                }
                last_path = p.clone();
                let offset = if attached { h.header_len } else { 0 };
                let (mut r, bound) = open_part(&h, p, offset, per_part)?;
                if bound < per_part.min(end - p0) && h.encoding == Encoding::Raw {
                    return Err(VolumeError::Truncated {
                        path: p.clone(),
                        what: what.clone(),
                        expected: per_part,
                        actual: bound,
                    });
                }
                if bound < per_part.min(end - p0) {
                    return Err(invalid(
                        p,
                        format!(
                            "truncated: {what} need {per_part} bytes but this gzip data can hold at most {bound}"
                        ),
                    ));
                }
                let lo = start.max(p0);
                let hi = end.min(p1);
                skip(&mut r, lo - p0, p, "earlier frames", 0)?;
                let dst = &mut out[(lo - start) as usize..(hi - start) as usize];
                for (c, chunk) in dst.chunks_mut(4 << 20).enumerate() {
                    read_all(&mut r, chunk, p, &what, lo - p0 + (c as u64) * (4 << 20))?;
                    let done = (lo - start) + (c as u64 + 1) * (4 << 20);
                    (reading.progress)(done.min(lay.frame_bytes), lay.frame_bytes);
                }
                if h.encoding == Encoding::Gzip {
                    finish_gzip(&mut r, p)?;
                }
            }
            data.fix_endianness(h.little_endian);
        }
        Encoding::Ascii | Encoding::Hex => {
            let offset = if attached { h.header_len } else { 0 };
            let text = read_text_parts(&h, &parts, offset, per_part, max_bytes)?;
            if let Some(p) = parts.last() {
                last_path = p.clone();
            }
            decode_text(
                &h,
                &text,
                start as usize / h.ty.size(),
                &mut data,
                &last_path,
                total,
            )?;
        }
    }
    Ok((volume(&h, &lay, data, path, reading.warnings), last_path))
}

/// Every value of a NRRD file in file order (fastest axis first), whatever its axes:
/// for callers that split non-spatial axes themselves (3D Slicer's layered
/// segmentations keep a `list` axis fastest).
pub fn read_all_values(h: &Header, path: &Path, max_bytes: u64) -> Result<VoxelData, VolumeError> {
    let n = h
        .sizes
        .iter()
        .try_fold(1usize, |acc, &s| acc.checked_mul(s))
        .filter(|&n| n.checked_mul(h.ty.size()).is_some_and(|b| b < 1 << 62))
        .ok_or_else(|| invalid(path, format!("sizes {:?} overflow", h.sizes)))?;
    let total = (n * h.ty.size()) as u64;
    if total > max_bytes {
        return Err(VolumeError::TooLarge {
            path: path.to_owned(),
            dims: format!("{:?}", h.sizes),
            ty: h.ty.name().into(),
            bytes: fmt_bytes(total),
            limit: fmt_bytes(max_bytes),
        });
    }
    let parts = data_paths(h, path);
    if !total.is_multiple_of(parts.len() as u64) {
        return Err(invalid(
            path,
            format!(
                "{total} bytes of values cannot be split evenly over {} data files",
                parts.len()
            ),
        ));
    }
    let per_part = total / parts.len() as u64;
    let offset = if h.data_files.is_empty() {
        h.header_len
    } else {
        0
    };
    let mut data = VoxelData::try_zeroed(h.ty, n)
        .ok_or_else(|| invalid(path, format!("cannot allocate {}", fmt_bytes(total))))?;
    let what = format!("{:?} {} values", h.sizes, h.ty);
    match h.encoding {
        Encoding::Raw | Encoding::Gzip => {
            let out = data.as_bytes_mut();
            for (k, p) in parts.iter().enumerate() {
                let (mut r, bound) = open_part(h, p, offset, per_part)?;
                if bound < per_part {
                    return Err(VolumeError::Truncated {
                        path: p.clone(),
                        what: what.clone(),
                        expected: per_part,
                        actual: bound,
                    });
                }
                let lo = k as u64 * per_part;
                read_all(
                    &mut r,
                    &mut out[lo as usize..(lo + per_part) as usize],
                    p,
                    &what,
                    0,
                )?;
                if h.encoding == Encoding::Gzip {
                    finish_gzip(&mut r, p)?;
                }
            }
            data.fix_endianness(h.little_endian);
        }
        Encoding::Ascii | Encoding::Hex => {
            let text = read_text_parts(h, &parts, offset, per_part, max_bytes)?;
            decode_text(h, &text, 0, &mut data, path, total)?;
        }
    }
    Ok(data)
}

/// The volume of decoded `data`, with the header's geometry and content.
fn volume(
    h: &Header,
    lay: &Layout,
    data: VoxelData,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Volume {
    let (spacing, orientation) = geometry(h, lay, path, warnings);
    Volume {
        dims: lay.dims,
        spacing,
        data,
        scaling: super::Scaling::IDENTITY,
        orientation,
        descriptions: h
            .content
            .iter()
            .map(|c| ("content".into(), c.clone()))
            .collect(),
    }
}

/// Parses ascii numbers or hex bytes into `data`, starting at value `first`.
fn decode_text(
    h: &Header,
    text: &[u8],
    first: usize,
    data: &mut VoxelData,
    path: &Path,
    total_bytes: u64,
) -> Result<(), VolumeError> {
    let n = data.len();
    let total_values = total_bytes / h.ty.size() as u64;
    if h.encoding == Encoding::Hex {
        let mut bytes = Vec::with_capacity(n * h.ty.size());
        let skip_bytes = first * h.ty.size();
        let mut hi: Option<u8> = None;
        let mut k = 0usize;
        for &c in text {
            if c.is_ascii_whitespace() {
                continue;
            }
            let v = (c as char)
                .to_digit(16)
                .ok_or_else(|| invalid(path, format!("hex data holds the non-hex byte {c:#04x}")))?
                as u8;
            match hi.take() {
                None => hi = Some(v),
                Some(h4) => {
                    if k >= skip_bytes && bytes.len() < n * h.ty.size() {
                        bytes.push(h4 << 4 | v);
                    }
                    k += 1;
                }
            }
        }
        if bytes.len() < n * h.ty.size() {
            return Err(VolumeError::Truncated {
                path: path.to_owned(),
                what: "hex voxels".into(),
                expected: total_bytes,
                actual: k as u64,
            });
        }
        data.as_bytes_mut().copy_from_slice(&bytes);
        data.fix_endianness(h.little_endian);
        return Ok(());
    }
    let s = String::from_utf8_lossy(text);
    let mut tokens = s
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty());
    for _ in 0..first {
        if tokens.next().is_none() {
            break;
        }
    }
    let mut count = first;
    let parse_err = |t: &str, i: usize| {
        invalid(
            path,
            format!(
                "ascii value {} at position {i} is not a {} number",
                short_name(t),
                h.ty
            ),
        )
    };
    with_voxels!(data, v => {
        for (i, slot) in v.iter_mut().enumerate() {
            let Some(t) = tokens.next() else {
                return Err(VolumeError::Truncated {
                    path: path.to_owned(),
                    what: format!("{total_values} ascii values"),
                    expected: total_values,
                    actual: count as u64,
                });
            };
            *slot = parse_num(t).ok_or_else(|| parse_err(t, first + i))?;
            count += 1;
        }
    });
    Ok(())
}

trait FromText: Sized {
    fn from_text(t: &str) -> Option<Self>;
}
macro_rules! from_text_int {
    ($($t:ty),*) => {$(impl FromText for $t {
        fn from_text(t: &str) -> Option<Self> {
            t.parse::<$t>().ok().or_else(|| {
                // "12.0" for an integer type: accept whole numbers only.
                let f = t.parse::<f64>().ok()?;
                (f.fract() == 0.0 && f >= <$t>::MIN as f64 && f <= <$t>::MAX as f64).then_some(f as $t)
            })
        }
    })*};
}
from_text_int!(u8, i8, u16, i16, u32, i32);
impl FromText for f32 {
    fn from_text(t: &str) -> Option<Self> {
        t.parse().ok()
    }
}
impl FromText for f64 {
    fn from_text(t: &str) -> Option<Self> {
        t.parse().ok()
    }
}
fn parse_num<T: FromText>(t: &str) -> Option<T> {
    T::from_text(t)
}

/// Parses a whole attached NRRD held in memory (fuzzing, mutation tests); `path` is
/// used in messages only. Detached data files are refused.
pub fn load_bytes(bytes: &[u8], max_bytes: u64, path: &Path) -> Result<Volume, VolumeError> {
    let end = bytes
        .windows(2)
        .position(|w| w == b"\n\n")
        .map(|p| (p + 2, p + 1))
        .or_else(|| {
            bytes
                .windows(4)
                .position(|w| w == b"\r\n\r\n")
                .map(|p| (p + 4, p + 2))
        });
    let (data_at, text_end) = end.unwrap_or((bytes.len(), bytes.len()));
    let text = String::from_utf8_lossy(&bytes[..text_end]);
    let h = parse_header(&text, path)?;
    if !h.data_files.is_empty() {
        return Err(invalid(
            path,
            "detached data files are not read from memory",
        ));
    }
    let lay = layout(
        &h,
        FrameRequest {
            frame: 0,
            max_bytes,
        },
        path,
    )?;
    let body = &bytes[data_at..];
    let n = lay.dims.iter().product::<usize>();
    let mut warnings = Vec::new();
    let mut data = VoxelData::try_zeroed(h.ty, n)
        .ok_or_else(|| invalid(path, "cannot allocate the voxels"))?;
    let body = &body[(h.byte_skip.max(0) as usize).min(body.len())..];
    match h.encoding {
        Encoding::Raw => {
            let need = lay.frame_bytes as usize;
            if body.len() < need {
                return Err(VolumeError::Truncated {
                    path: path.to_owned(),
                    what: "voxels".into(),
                    expected: need as u64,
                    actual: body.len() as u64,
                });
            }
            data.as_bytes_mut().copy_from_slice(&body[..need]);
            data.fix_endianness(h.little_endian);
        }
        Encoding::Gzip => {
            if (body.len() as u64).saturating_mul(MAX_DEFLATE_RATIO) < lay.frame_bytes {
                return Err(invalid(path, "gzip data too short for the voxels"));
            }
            let mut r = flate2::read::MultiGzDecoder::new(body);
            read_all(&mut r, data.as_bytes_mut(), path, "voxels", 0)?;
            finish_gzip(&mut r, path)?;
            data.fix_endianness(h.little_endian);
        }
        Encoding::Ascii | Encoding::Hex => {
            if body.len() as u64 > max_bytes.saturating_mul(24) {
                return Err(invalid(path, "text too long"));
            }
            decode_text(&h, body, 0, &mut data, path, lay.frame_bytes)?;
        }
    }
    Ok(volume(&h, &lay, data, path, &mut warnings))
}

/// Writes an attached, gzip-compressed `.nrrd` in LPS space (as 3D Slicer writes).
/// NRRD has no slope/intercept: scaled volumes are written as their physical values.
pub fn save(volume: &Volume, path: &Path, warnings: &mut Vec<String>) -> Result<(), VolumeError> {
    let physical;
    let data = if volume.scaling.is_identity() {
        &volume.data
    } else {
        physical = super::physical_values(volume);
        warnings.push(format!(
            "NRRD has no slope/intercept field: writing physical values (slope {}, intercept {}) as {}",
            volume.scaling.slope,
            volume.scaling.inter,
            physical.voxel_type()
        ));
        &physical
    };
    let ty = match data.voxel_type() {
        VoxelType::U8 => "uint8",
        VoxelType::I8 => "int8",
        VoxelType::U16 => "uint16",
        VoxelType::I16 => "int16",
        VoxelType::U32 => "uint32",
        VoxelType::I32 => "int32",
        VoxelType::F32 => "float",
        VoxelType::F64 => "double",
    };
    let lps = DVec3::new(-1.0, -1.0, 1.0);
    let l = volume.orientation.linear;
    let v = |c: DVec3| {
        let c = c * lps;
        format!("({},{},{})", c.x, c.y, c.z)
    };
    let o = volume.orientation.offset * lps;
    let mut header = format!(
        "NRRD0004\n# written by volao\ntype: {ty}\ndimension: 3\nspace: left-posterior-superior\nsizes: {} {} {}\nspace directions: {} {} {}\nkinds: domain domain domain\nendian: little\nencoding: gzip\nspace origin: ({},{},{})\n",
        volume.dims[0],
        volume.dims[1],
        volume.dims[2],
        v(l.x_axis),
        v(l.y_axis),
        v(l.z_axis),
        o.x,
        o.y,
        o.z
    );
    if let Some((_, text)) = volume.descriptions.first() {
        let clean: String = text.chars().filter(|c| !c.is_control()).take(200).collect();
        header.push_str(&format!("content: {clean}\n"));
    }
    header.push('\n');
    let file = std::fs::File::create(path).map_err(|e| VolumeError::io(path, e))?;
    let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
    let result = (|| -> std::io::Result<()> {
        w.write_all(header.as_bytes())?;
        let mut gz = flate2::write::GzEncoder::new(&mut w, flate2::Compression::default());
        if cfg!(target_endian = "little") {
            gz.write_all(data.as_bytes())?;
        } else {
            let mut swapped = data.clone();
            swapped.swap_bytes();
            gz.write_all(swapped.as_bytes())?;
        }
        gz.finish()?;
        w.flush()
    })();
    result.map_err(|e| VolumeError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("t.nrrd")
    }

    #[test]
    fn ascii_4d_reads_frames_and_refuses_one_too_many() {
        let text = "NRRD0005\ntype: uint8\nencoding: ascii\ndimension: 4\nsizes: 2 1 1 3\nspace: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1) none\n\n1 2 3 4 5 6\n";
        let v = load_bytes(text.as_bytes(), 1 << 20, p()).expect("loads");
        assert_eq!(v.dims, [2, 1, 1]);
        assert_eq!(v.data, VoxelData::U8(vec![1, 2]));
        let header = text.split("\n\n").next().unwrap_or_default();
        let h = parse_header(header, p()).expect("header");
        let want = FrameRequest {
            frame: 3,
            max_bytes: 1 << 20,
        };
        let err = layout(&h, want, p()).expect_err("frame 3 of 3");
        assert!(err.to_string().contains("count from 0"), "{err}");
    }

    #[test]
    fn colour_axis_is_refused_naming_the_kind() {
        let text = "NRRD0004\ntype: uint8\nencoding: raw\ndimension: 3\nsizes: 3 4 4\nkinds: RGB-color domain domain\n\n";
        let err = load_bytes(text.as_bytes(), 1 << 20, p()).expect_err("RGB");
        assert!(err.to_string().contains("RGB-color"), "{err}");
    }

    #[test]
    fn key_value_pairs_are_kept_even_with_colons_in_values() {
        let text = "NRRD0004\ntype: uint8\nencoding: raw\ndimension: 1\nsizes: 1\nSegment0_Name:=ribs\nParams:=Range: 0.0|a\\nb\ncontent: a:=b\n";
        let h = parse_header(text, p()).expect("parses");
        assert_eq!(
            h.key_values,
            vec![
                ("Segment0_Name".to_owned(), "ribs".to_owned()),
                ("Params".to_owned(), "Range: 0.0|a\nb".to_owned()),
            ]
        );
        assert_eq!(h.content.as_deref(), Some("a:=b"));
    }

    #[test]
    fn sprintf_patterns() {
        assert_eq!(sprintf_int("s%03d.raw", 7).as_deref(), Some("s007.raw"));
        assert_eq!(sprintf_int("s%d.raw", 12).as_deref(), Some("s12.raw"));
        assert_eq!(sprintf_int("s%s.raw", 1), None);
    }

    #[test]
    fn lps_directions_become_ras() {
        let text = "NRRD0004\ntype: uint8\nencoding: raw\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\nspace directions: (2,0,0) (0,3,0) (0,0,4)\nspace origin: (1,2,3)\n\n\0\0\0\0\0\0\0\0";
        let v = load_bytes(text.as_bytes(), 1 << 20, p()).expect("loads");
        assert_eq!(v.spacing, [2.0, 3.0, 4.0]);
        assert_eq!(v.orientation.axis_codes(), "LPS");
        assert_eq!(v.orientation.offset, DVec3::new(-1.0, -2.0, 3.0));
    }
}
