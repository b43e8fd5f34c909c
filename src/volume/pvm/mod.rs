//! PVM / PVM2 / PVM3 volumes from the V³ Volume Library, optionally DDS-compressed (libmini's ddsbase format).
//!
//! # The format (as read and written by Stefan Roettger's libmini, `ddsbase.cpp`)
//!
//! A PVM file is a short ASCII header followed by the raw voxels, x fastest:
//!
//! ```text
//! PVM\n  [#comment\n …]  W H D\n                C\n  voxels
//! PVM2\n                 W H D\n  SX SY SZ\n    C\n  voxels
//! PVM3\n                 W H D\n  SX SY SZ\n    C\n  voxels  description\0 courtesy\0 parameter\0 comment\0
//! ```
//!
//! `C` is the number of bytes per voxel: 1 for `u8`, 2 for `u16` stored big-endian
//! (most significant byte first). `SX SY SZ` is the voxel spacing. PVM3 appends four
//! NUL-terminated strings after the voxels (any of them may be empty). Lines starting
//! with `#` may follow the magic line (libmini writes them only in plain PVM).
//!
//! Most files of the Volume Library are additionally compressed with libmini's
//! *Differential Data Stream*: the file starts with `DDS v3d\n` or `DDS v3e\n` and the
//! rest is a bit stream that decompresses to a complete PVM file as above
//! (`readDDSfile` + `readPVMvolume`). The bit stream, read most significant bit first:
//!
//! * 2 bits `skip − 1` (1‥4; libmini writes the bytes per voxel) and 16 bits `strip − 1`
//!   (1‥65536; libmini writes the volume width);
//! * runs: a 7-bit count `n` (0 ends the stream; libmini writes no terminator and relies
//!   on the zero padding after the last byte), a 3-bit code `k` giving the width
//!   `w = 0` for `k = 0` and `w = k + 1` otherwise, then `n` values of `w` bits each;
//! * each value `v` is a difference `d = v − 2^w / 2` and the output byte is
//!   `x[i] = x[i−1] + d (+ x[i−strip] − x[i−strip−1] when strip > 1 and i > strip)`
//!   modulo 256, starting from `x[−1] = 0` (`DDS_decode`);
//! * the decoded bytes are *planar*: the encoder first split the file into `skip`
//!   byte planes (all bytes at positions ≡ 0 mod skip, then ≡ 1, …), so for 16-bit
//!   volumes the high bytes and the low bytes are compressed separately
//!   (`DDS_deinterleave`). "v3d" splits the whole stream at once; "v3e" (written by
//!   libmini for streams longer than 2^24 bytes) splits it in independent blocks of
//!   `skip × 2^24` bytes, the last one shorter (`DDS_interleave(…, DDS_INTERLEAVE)`).
//!
//! # Safety against malformed input
//!
//! Every size is computed with checked or 128-bit arithmetic and compared with the
//! caller's `max_voxel_bytes` before anything is allocated; the DDS stream is measured
//! in a first pass that stores nothing, so a stream that would decompress to more than
//! `max_voxel_bytes` + [`HEADER_ALLOWANCE`] is refused before its buffer exists. Every
//! decoder loop consumes input or is bounded by a size that was checked, and all
//! slice accesses go through `get`.
//!
//! Memory: a plain file needs one copy of the voxels beyond the input bytes. A DDS file
//! needs the decompressed stream; 8-bit voxels are cut out of it in place, 16-bit voxels
//! are converted into a second buffer, so the peak is about twice the voxel payload.

mod dds;
mod error;

use dds::{Planes, dds_decode_with, dds_decoded_len};
pub use error::{HEADER_ALLOWANCE, Layout, PvmError};
use error::{copy_bytes, try_with_capacity, u16_from_be, zeroed};
use std::borrow::Cow;
use std::io::Write;

/// Magic of a DDS stream whose byte planes span the whole stream (libmini `DDS_ID`).
const DDS_V3D_MAGIC: &[u8] = b"DDS v3d\n";
/// Magic of a DDS stream split into planes block by block (libmini `DDS_ID2`).
const DDS_V3E_MAGIC: &[u8] = b"DDS v3e\n";
/// libmini `DDS_INTERLEAVE`: a v3e block holds `skip ×` this many bytes.
const V3E_INTERLEAVE_BLOCK: usize = 1 << 24;
/// The ASCII header (magic, optional `#` comments, sizes) must end within this many bytes.
const MAX_HEADER_BYTES: usize = 64 * 1024;
/// Most decoded bytes spent on finding the header of a DDS stream that is over the
/// caller's limit (only to name its dimensions in the error; 16-bit volumes need about
/// half the stream because their low bytes form the second plane).
const MAX_PEEK_BYTES: usize = 256 << 20;
/// Labels of the four PVM3 strings, in file order.
const STRING_LABELS: [&str; 4] = ["description", "courtesy", "parameter", "comment"];

/// Header flavour: `PVM` (no spacing), `PVM2` (spacing), `PVM3` (spacing + strings).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PvmVersion {
    Pvm1,
    Pvm2,
    Pvm3,
}

/// DDS compression flavour: `v3d` (planes over the whole stream) or `v3e` (blockwise).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DdsVersion {
    V3d,
    V3e,
}

/// Voxels, x fastest. 16-bit voxels are big-endian in the file and native `u16` here.
#[derive(Debug, Clone, PartialEq)]
pub enum PvmVoxels {
    U8(Vec<u8>),
    U16(Vec<u16>),
}

impl PvmVoxels {
    /// Number of voxels.
    pub fn len(&self) -> usize {
        match self {
            PvmVoxels::U8(v) => v.len(),
            PvmVoxels::U16(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes per voxel, the header's component count.
    pub fn bytes_per_voxel(&self) -> usize {
        match self {
            PvmVoxels::U8(_) => 1,
            PvmVoxels::U16(_) => 2,
        }
    }
}

/// Borrowed voxels to write, so saving needs no copy of the volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PvmSamples<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
}

impl PvmSamples<'_> {
    fn len(&self) -> usize {
        match self {
            PvmSamples::U8(v) => v.len(),
            PvmSamples::U16(v) => v.len(),
        }
    }

    fn bytes_per_voxel(&self) -> usize {
        match self {
            PvmSamples::U8(_) => 1,
            PvmSamples::U16(_) => 2,
        }
    }
}

impl PvmVoxels {
    /// A borrowed view for [`write_pvm3`].
    pub fn samples(&self) -> PvmSamples<'_> {
        match self {
            PvmVoxels::U8(v) => PvmSamples::U8(v),
            PvmVoxels::U16(v) => PvmSamples::U16(v),
        }
    }
}

/// A decoded PVM file.
#[derive(Debug, Clone, PartialEq)]
pub struct PvmVolume {
    /// Voxel counts along x, y, z (x fastest in `voxels`).
    pub dims: [usize; 3],
    /// Voxel spacing; `None` for plain PVM (v1), which stores none.
    pub spacing: Option<[f32; 3]>,
    pub voxels: PvmVoxels,
    /// PVM3 strings after the voxels as (label, text) with labels "description",
    /// "courtesy", "parameter", "comment"; empty strings are omitted.
    pub descriptions: Vec<(String, String)>,
    /// Which header the (decompressed) file had.
    pub version: PvmVersion,
    /// `Some` if the file was DDS-compressed.
    pub compression: Option<DdsVersion>,
}

/// Reads a PVM, PVM2 or PVM3 file, DDS-compressed or not (libmini `readPVMvolume`).
///
/// `max_voxel_bytes` caps the memory spent on voxels: a header claiming more voxel
/// bytes, or a DDS stream decompressing to more than `max_voxel_bytes` +
/// [`HEADER_ALLOWANCE`] bytes, is refused before anything of that size is allocated.
pub fn read_pvm(bytes: &[u8], max_voxel_bytes: u64) -> Result<PvmVolume, PvmError> {
    if let Some(stream) = bytes.strip_prefix(DDS_V3D_MAGIC) {
        let source = decompress_dds(stream, 0, max_voxel_bytes)?;
        return parse_pvm(source, Some(DdsVersion::V3d), max_voxel_bytes);
    }
    if let Some(stream) = bytes.strip_prefix(DDS_V3E_MAGIC) {
        let source = decompress_dds(stream, V3E_INTERLEAVE_BLOCK, max_voxel_bytes)?;
        return parse_pvm(source, Some(DdsVersion::V3e), max_voxel_bytes);
    }
    parse_pvm(Source::Plain(bytes), None, max_voxel_bytes)
}

/// Writes an uncompressed PVM3 file that [`read_pvm`] and libmini's `readPVMvolume` read
/// back (the layout of libmini `writePVMvolume` before its DDS compression step).
///
/// The spacing is written in Rust's shortest round-trip notation, so it reads back
/// bit-exactly. `descriptions` fill the four PVM3 strings by label ("description",
/// "courtesy", "parameter", "comment", ASCII case-insensitive); several texts for one
/// label are joined with newlines, and texts under any other label are appended to the
/// comment as "label: text" lines so that nothing is silently dropped.
pub fn write_pvm3<W: Write>(
    mut out: W,
    dims: [usize; 3],
    spacing: [f32; 3],
    voxels: PvmSamples<'_>,
    descriptions: &[(String, String)],
) -> Result<(), PvmError> {
    let [w, h, d] = dims;
    if dims.contains(&0) {
        return Err(PvmError::InvalidInput(format!(
            "dimensions {w}×{h}×{d} contain a zero"
        )));
    }
    if dims.iter().any(|&n| u32::try_from(n).is_err()) {
        return Err(PvmError::InvalidInput(format!(
            "dimensions {w}×{h}×{d} exceed libmini's 32-bit limit of {} per axis",
            u32::MAX
        )));
    }
    let count = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(d))
        .ok_or_else(|| PvmError::InvalidInput(format!("dimensions {w}×{h}×{d} overflow")))?;
    if voxels.len() != count {
        return Err(PvmError::InvalidInput(format!(
            "{} voxels given for dimensions {w}×{h}×{d} ({count} expected)",
            voxels.len()
        )));
    }
    if !spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err(PvmError::InvalidInput(format!(
            "voxel spacing {} {} {} is not finite and positive",
            spacing[0], spacing[1], spacing[2]
        )));
    }
    let strings = string_slots(descriptions)?;

    let [sx, sy, sz] = spacing;
    let header = format!(
        "PVM3\n{w} {h} {d}\n{sx} {sy} {sz}\n{}\n",
        voxels.bytes_per_voxel()
    );
    out.write_all(header.as_bytes())?;
    match voxels {
        PvmSamples::U8(v) => out.write_all(v)?,
        PvmSamples::U16(v) => {
            // Big-endian, converted in chunks so no second copy of the volume exists.
            let mut buf = Vec::with_capacity(64 * 1024);
            for chunk in v.chunks(32 * 1024) {
                buf.clear();
                for value in chunk {
                    buf.extend_from_slice(&value.to_be_bytes());
                }
                out.write_all(&buf)?;
            }
        }
    }
    for text in &strings {
        out.write_all(text.as_bytes())?;
        out.write_all(&[0])?;
    }
    out.flush()?;
    Ok(())
}

/// Sorts (label, text) pairs into the four PVM3 string slots; see [`write_pvm3`].
fn string_slots(descriptions: &[(String, String)]) -> Result<[String; 4], PvmError> {
    let mut slots: [String; 4] = Default::default();
    for (label, text) in descriptions {
        if text.is_empty() {
            continue;
        }
        if text.contains('\0') {
            return Err(PvmError::InvalidInput(format!(
                "the {label:?} text contains a NUL byte, which PVM3 strings cannot hold"
            )));
        }
        let known = STRING_LABELS
            .iter()
            .position(|l| l.eq_ignore_ascii_case(label));
        let (slot, entry) = match known {
            Some(i) => (i, text.clone()),
            None => (3, format!("{label}: {text}")),
        };
        if let Some(s) = slots.get_mut(slot) {
            if !s.is_empty() {
                s.push('\n');
            }
            s.push_str(&entry);
        }
    }
    Ok(slots)
}

// ---------------------------------------------------------------------------------------
// PVM header and body (libmini readPVMvolume)
// ---------------------------------------------------------------------------------------

/// The parsed ASCII header.
#[derive(Debug)]
struct Header {
    version: PvmVersion,
    dims: [u64; 3],
    spacing: Option<[f32; 3]>,
    /// Bytes per voxel, 1 or 2.
    components: u64,
    /// Offset of the first voxel byte.
    data_offset: usize,
}

impl Header {
    /// Voxel payload in bytes; cannot overflow because each dimension fits in 32 bits.
    fn layout(&self) -> Layout {
        Layout {
            dims: self.dims,
            components: self.components,
        }
    }

    fn voxel_bytes(&self) -> u128 {
        self.dims.iter().map(|&d| u128::from(d)).product::<u128>() * u128::from(self.components)
    }
}

/// Parses the ASCII header at the start of `data` (libmini `readPVMvolume`'s sscanf
/// steps), line by line: magic, `#` comment lines, dimensions, spacing (PVM2/3),
/// components. The voxels start after the newline that ends the component line.
/// (libmini's DDS reader skips comments only in plain PVM, its uncompressed `pnmbase`
/// reader in every version; a dimension line never starts with `#`, so we skip them
/// everywhere.)
fn parse_header(data: &[u8], in_dds: bool) -> Result<Header, PvmError> {
    let not_pvm = || {
        let start = show(data.get(..8).unwrap_or(data));
        if in_dds {
            PvmError::NotPvmInDds { start }
        } else {
            PvmError::NotPvm { start }
        }
    };
    if !data.starts_with(b"PVM") {
        return Err(not_pvm());
    }
    let mut lines = Lines { data, pos: 0 };
    let magic = lines.next("magic")?;
    let version = match magic {
        b"PVM" => PvmVersion::Pvm1,
        b"PVM2" => PvmVersion::Pvm2,
        b"PVM3" => PvmVersion::Pvm3,
        other if other.len() <= 8 => return Err(PvmError::UnsupportedVariant(show(other))),
        _ => return Err(not_pvm()),
    };

    let mut dim_line = lines.next("dimension")?;
    while dim_line.first() == Some(&b'#') {
        dim_line = lines.next("dimension")?;
    }
    let dims = parse_fields::<u64, 3>(dim_line, "dimension line", "three integers")?;
    if dims.contains(&0) {
        return Err(PvmError::ZeroDims { dims });
    }
    if let Some(big) = dims.iter().find(|&&d| d > u64::from(u32::MAX)) {
        return Err(PvmError::BadHeader(format!(
            "dimension {big} exceeds libmini's 32-bit limit of {}",
            u32::MAX
        )));
    }

    let spacing = if version == PvmVersion::Pvm1 {
        None
    } else {
        let spacing_line = lines.next("spacing")?;
        let spacing = parse_fields::<f32, 3>(spacing_line, "spacing line", "three numbers")?;
        if !spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(PvmError::BadSpacing { spacing });
        }
        Some(spacing)
    };

    let component_line = lines.next("component")?;
    let [components] = parse_fields::<u64, 1>(component_line, "component line", "one integer")?;
    if components != 1 && components != 2 {
        return Err(PvmError::UnsupportedComponents(components));
    }
    Ok(Header {
        version,
        dims,
        spacing,
        components,
        data_offset: lines.pos,
    })
}

/// Newline-terminated lines of the header.
struct Lines<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Lines<'a> {
    /// The next line without its `\n` (and without a trailing `\r`).
    fn next(&mut self, what: &'static str) -> Result<&'a [u8], PvmError> {
        let rest = self.data.get(self.pos..).unwrap_or_default();
        let Some(len) = rest.iter().position(|&b| b == b'\n') else {
            return Err(if self.data.len() >= MAX_HEADER_BYTES {
                PvmError::BadHeader(format!(
                    "no end of the {what} line within the first {MAX_HEADER_BYTES} bytes"
                ))
            } else {
                PvmError::TruncatedHeader(what)
            });
        };
        self.pos = self.pos.saturating_add(len + 1);
        let line = rest.get(..len).unwrap_or_default();
        Ok(line.strip_suffix(b"\r").unwrap_or(line))
    }
}

/// Splits a header line into exactly `N` whitespace-separated numbers.
fn parse_fields<T: std::str::FromStr + Copy + Default, const N: usize>(
    line: &[u8],
    what: &str,
    expected: &str,
) -> Result<[T; N], PvmError> {
    let bad = || PvmError::BadHeader(format!("{what} \"{}\" should hold {expected}", show(line)));
    let text = std::str::from_utf8(line).map_err(|_| bad())?;
    let mut fields = text.split_ascii_whitespace();
    let mut values = [T::default(); N];
    for value in &mut values {
        *value = fields.next().and_then(|f| f.parse().ok()).ok_or_else(bad)?;
    }
    if fields.next().is_some() {
        return Err(bad());
    }
    Ok(values)
}

/// Up to 40 bytes, printable ASCII kept and everything else escaped, for messages.
fn show(bytes: &[u8]) -> String {
    let cut = bytes.get(..40).unwrap_or(bytes);
    let mut s = cut.escape_ascii().to_string();
    if cut.len() < bytes.len() {
        s.push('…');
    }
    s
}

/// Header, voxels and PVM3 strings out of a plain or decompressed file
/// (libmini `readPVMvolume` after `readDDSfile`). Sizes are checked before any copy:
/// the voxels must all be there, fit the caller's limit, and be followed by exactly
/// the four PVM3 strings (PVM3) or by nothing (PVM, PVM2), as libmini requires.
fn parse_pvm(
    source: Source<'_>,
    compression: Option<DdsVersion>,
    max_voxel_bytes: u64,
) -> Result<PvmVolume, PvmError> {
    let len = source.len();
    let header = {
        let prefix = source.bytes(0, MAX_HEADER_BYTES);
        parse_header(&prefix, compression.is_some())?
    };
    let expected = header.voxel_bytes();
    let available = len.saturating_sub(header.data_offset);
    if expected > available as u128 {
        return Err(PvmError::Truncated {
            layout: header.layout(),
            expected,
            actual: available as u64,
        });
    }
    if expected > u128::from(max_voxel_bytes) {
        return Err(PvmError::TooLarge {
            layout: header.layout(),
            bytes: expected,
            limit: max_voxel_bytes,
        });
    }
    // Both conversions fit: `expected` ≤ `available` ≤ `len`, a usize, and so are the dims.
    let voxel_bytes = usize::try_from(expected).map_err(|_| PvmError::OutOfMemory(u64::MAX))?;
    let dims = header
        .dims
        .map(|d| usize::try_from(d).unwrap_or(usize::MAX));
    let end = header.data_offset.saturating_add(voxel_bytes);

    let descriptions = if header.version == PvmVersion::Pvm3 {
        parse_strings(&source.bytes(end, len))?
    } else if len > end {
        return Err(PvmError::TrailingBytes {
            count: (len - end) as u64,
            after: "voxel data",
        });
    } else {
        Vec::new()
    };

    let voxels = source.into_voxels(header.data_offset, voxel_bytes, header.components)?;
    Ok(PvmVolume {
        dims,
        spacing: header.spacing,
        voxels,
        descriptions,
        version: header.version,
        compression,
    })
}

/// The four NUL-terminated PVM3 strings after the voxels; empty ones are omitted.
/// Text that is not UTF-8 is read as Latin-1 (the Volume Library predates UTF-8).
fn parse_strings(mut rest: &[u8]) -> Result<Vec<(String, String)>, PvmError> {
    let mut out = Vec::new();
    for label in STRING_LABELS {
        let nul = rest
            .iter()
            .position(|&b| b == 0)
            .ok_or(PvmError::TruncatedStrings(label))?;
        let (text, after) = rest
            .split_at_checked(nul)
            .ok_or(PvmError::TruncatedStrings(label))?;
        if !text.is_empty() {
            let text = match std::str::from_utf8(text) {
                Ok(s) => s.to_owned(),
                Err(_) => text.iter().map(|&b| char::from(b)).collect(),
            };
            out.push((label.to_owned(), text));
        }
        rest = after.get(1..).unwrap_or_default();
    }
    if !rest.is_empty() {
        return Err(PvmError::TrailingBytes {
            count: rest.len() as u64,
            after: "four PVM3 strings",
        });
    }
    Ok(out)
}

/// The bytes of a PVM file: the input itself, or a decompressed DDS stream still in
/// its planar layout (see [`Planes`]), read through the plane mapping instead of being
/// re-interleaved into a second buffer.
enum Source<'a> {
    Plain(&'a [u8]),
    Decoded { planar: Vec<u8>, planes: Planes },
}

impl Source<'_> {
    fn len(&self) -> usize {
        match self {
            Source::Plain(b) => b.len(),
            Source::Decoded { planar, .. } => planar.len(),
        }
    }

    /// File bytes `start..end` (clamped to the data), borrowed where they are contiguous.
    fn bytes(&self, start: usize, end: usize) -> Cow<'_, [u8]> {
        let end = end.min(self.len());
        let start = start.min(end);
        match self {
            Source::Plain(b) => Cow::Borrowed(b.get(start..end).unwrap_or_default()),
            Source::Decoded { planar, planes } if planes.skip <= 1 => {
                Cow::Borrowed(planar.get(start..end).unwrap_or_default())
            }
            Source::Decoded { planar, planes } => {
                let mut out = vec![0u8; end - start];
                planes.gather(planar, start, end, |i, b| {
                    if let Some(x) = out.get_mut(i) {
                        *x = b;
                    }
                });
                Cow::Owned(out)
            }
        }
    }

    /// The `len` voxel bytes at `start` as `u8` or big-endian `u16` voxels. 8-bit voxels
    /// of a decompressed stream without planes are cut out of its buffer in place.
    fn into_voxels(self, start: usize, len: usize, components: u64) -> Result<PvmVoxels, PvmError> {
        let end = start
            .checked_add(len)
            .filter(|&e| e <= self.len())
            .ok_or_else(|| {
                PvmError::BadHeader(format!(
                    "voxel range {start}+{len} lies outside the {} bytes of data",
                    self.len()
                ))
            })?;
        let two = components == 2;
        match self {
            Source::Plain(bytes) => {
                let voxels = bytes.get(start..end).unwrap_or_default();
                if two {
                    Ok(PvmVoxels::U16(u16_from_be(voxels)?))
                } else {
                    Ok(PvmVoxels::U8(copy_bytes(voxels)?))
                }
            }
            Source::Decoded { planar, planes } if planes.skip <= 1 && two => Ok(PvmVoxels::U16(
                u16_from_be(planar.get(start..end).unwrap_or_default())?,
            )),
            Source::Decoded { mut planar, planes } if planes.skip <= 1 => {
                planar.truncate(end);
                planar.drain(..start);
                Ok(PvmVoxels::U8(planar))
            }
            Source::Decoded { planar, planes } if two => {
                let mut out = zeroed::<u16>(len / 2)?;
                planes.gather(&planar, start, end, |i, b| {
                    if let Some(v) = out.get_mut(i / 2) {
                        *v |= if i % 2 == 0 {
                            u16::from(b) << 8
                        } else {
                            u16::from(b)
                        };
                    }
                });
                Ok(PvmVoxels::U16(out))
            }
            Source::Decoded { planar, planes } => {
                let mut out = zeroed::<u8>(len)?;
                planes.gather(&planar, start, end, |i, b| {
                    if let Some(x) = out.get_mut(i) {
                        *x = b;
                    }
                });
                Ok(PvmVoxels::U8(out))
            }
        }
    }
}

/// Decompresses a DDS stream (the bytes after its magic) into a [`Source`] (libmini
/// `readDDSfile`). `block` is 0 for v3d and `DDS_INTERLEAVE` for v3e.
///
/// Pass 1 measures the output; if it exceeds `max_voxel_bytes` + [`HEADER_ALLOWANCE`]
/// the stream is refused, naming the header's dimensions when the header can be
/// decoded without storing the stream. Pass 2 decodes into a buffer of exactly that size.
fn decompress_dds(
    stream: &[u8],
    block: usize,
    max_voxel_bytes: u64,
) -> Result<Source<'static>, PvmError> {
    let (params, total) = dds_decoded_len(stream)?;
    if total == 0 {
        return Err(PvmError::CorruptDds("the stream decodes to no data".into()));
    }
    let too_long = || PvmError::DdsTooLarge {
        bytes: total,
        limit: max_voxel_bytes,
    };
    let len = usize::try_from(total).map_err(|_| too_long())?;
    let planes = Planes {
        skip: params.skip,
        block_bytes: if block == 0 {
            0
        } else {
            block.saturating_mul(params.skip)
        },
        len,
    };
    if total > max_voxel_bytes.saturating_add(HEADER_ALLOWANCE) {
        if let Some(prefix) = dds_peek(stream, planes, MAX_HEADER_BYTES.min(len))? {
            let header = parse_header(&prefix, true)?;
            if header.voxel_bytes() > u128::from(max_voxel_bytes) {
                return Err(PvmError::TooLarge {
                    layout: header.layout(),
                    bytes: header.voxel_bytes(),
                    limit: max_voxel_bytes,
                });
            }
        }
        return Err(too_long());
    }
    let mut planar = try_with_capacity::<u8>(len)?;
    dds_decode_with(stream, |_, b| {
        planar.push(b);
        planar.len() < len
    })?;
    if planar.len() != len {
        return Err(PvmError::CorruptDds(format!(
            "decoded {} bytes where the first pass counted {len}",
            planar.len()
        )));
    }
    Ok(Source::Decoded { planar, planes })
}

/// The first `n` file bytes of a DDS stream, decoded without storing the rest: each
/// wanted file position is mapped to its planar index and picked up as it streams by.
/// `None` if that would mean decoding more than [`MAX_PEEK_BYTES`].
fn dds_peek(stream: &[u8], planes: Planes, n: usize) -> Result<Option<Vec<u8>>, PvmError> {
    let mut wanted: Vec<(usize, usize)> = (0..n).map(|pos| (planes.index(pos), pos)).collect();
    wanted.sort_unstable();
    if wanted.last().is_some_and(|&(idx, _)| idx >= MAX_PEEK_BYTES) {
        return Ok(None);
    }
    let mut out = vec![0u8; n];
    let mut next = 0;
    dds_decode_with(stream, |i, b| {
        while let Some(&(idx, pos)) = wanted.get(next) {
            if idx > i {
                break;
            }
            if idx == i
                && let Some(x) = out.get_mut(pos)
            {
                *x = b;
            }
            next += 1;
        }
        next < wanted.len()
    })?;
    Ok(Some(out))
}

#[cfg(test)]
mod tests;
