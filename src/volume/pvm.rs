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

use std::borrow::Cow;
use std::fmt;
use std::io::Write;

/// Magic of a DDS stream whose byte planes span the whole stream (libmini `DDS_ID`).
const DDS_V3D_MAGIC: &[u8] = b"DDS v3d\n";
/// Magic of a DDS stream split into planes block by block (libmini `DDS_ID2`).
const DDS_V3E_MAGIC: &[u8] = b"DDS v3e\n";
/// libmini `DDS_INTERLEAVE`: a v3e block holds `skip ×` this many bytes.
const V3E_INTERLEAVE_BLOCK: usize = 1 << 24;
/// libmini `DDS_RL`: width of a run's count field.
const DDS_RUN_BITS: u32 = 7;
/// The ASCII header (magic, optional `#` comments, sizes) must end within this many bytes.
const MAX_HEADER_BYTES: usize = 64 * 1024;
/// Most decoded bytes spent on finding the header of a DDS stream that is over the
/// caller's limit (only to name its dimensions in the error; 16-bit volumes need about
/// half the stream because their low bytes form the second plane).
const MAX_PEEK_BYTES: usize = 256 << 20;
/// Labels of the four PVM3 strings, in file order.
const STRING_LABELS: [&str; 4] = ["description", "courtesy", "parameter", "comment"];

/// How many bytes a decompressed DDS stream may hold beyond `max_voxel_bytes`: room for
/// the ASCII header and the PVM3 strings.
pub const HEADER_ALLOWANCE: u64 = 1 << 20;

/// Everything that can go wrong reading or writing a PVM file. Messages are one line.
#[derive(Debug, thiserror::Error)]
pub enum PvmError {
    #[error(
        "not a PVM file (starts with \"{start}\"; expected PVM, PVM2, PVM3, DDS v3d or DDS v3e)"
    )]
    NotPvm { start: String },
    #[error(
        "DDS-compressed file holds no PVM volume (its decompressed data starts with \"{start}\")"
    )]
    NotPvmInDds { start: String },
    #[error(
        "unsupported PVM variant \"{0}\" (only PVM, PVM2 and PVM3 with 1 or 2 bytes per voxel are supported)"
    )]
    UnsupportedVariant(String),
    #[error("truncated: the data ends inside the PVM header, before the end of its {0} line")]
    TruncatedHeader(&'static str),
    #[error("bad PVM header: {0}")]
    BadHeader(String),
    #[error("PVM header has a zero dimension ({}×{}×{})", dims[0], dims[1], dims[2])]
    ZeroDims { dims: [u64; 3] },
    #[error("PVM voxel spacing {} {} {} is not finite and positive", spacing[0], spacing[1], spacing[2])]
    BadSpacing { spacing: [f32; 3] },
    #[error(
        "unsupported PVM component count {0} (only 1 or 2 bytes per voxel; libmini's 3/4-component RGB/RGBA volumes are not supported)"
    )]
    UnsupportedComponents(u64),
    #[error(
        "truncated: header says {} = {expected} bytes of voxels but only {actual} follow",
        Layout { dims: *dims, components: *components }
    )]
    Truncated {
        dims: [u64; 3],
        components: u64,
        expected: u128,
        actual: u64,
    },
    #[error(
        "volume too large: header says {} = {bytes} bytes of voxels, more than the limit of {limit} bytes",
        Layout { dims: *dims, components: *components }
    )]
    TooLarge {
        dims: [u64; 3],
        components: u64,
        bytes: u128,
        limit: u64,
    },
    #[error(
        "truncated: the PVM3 file ends inside its {0} string (four NUL-terminated strings must follow the voxels)"
    )]
    TruncatedStrings(&'static str),
    #[error("{count} unexpected bytes after the {after}")]
    TrailingBytes { count: u64, after: &'static str },
    #[error("corrupt DDS stream: {0}")]
    CorruptDds(String),
    #[error(
        "DDS stream decompresses to {bytes} bytes, more than the limit of {limit} bytes of voxels plus {} bytes of header",
        HEADER_ALLOWANCE
    )]
    DdsTooLarge { bytes: u64, limit: u64 },
    #[error("out of memory: cannot allocate {0} bytes for PVM data")]
    OutOfMemory(u64),
    #[error("cannot write PVM: {0}")]
    InvalidInput(String),
    #[error("I/O error while writing PVM: {0}")]
    Io(#[from] std::io::Error),
}

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

/// "301×324×56 × 1 byte", for messages.
struct Layout {
    dims: [u64; 3],
    components: u64,
}

impl fmt::Display for Layout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.dims;
        let unit = if self.components == 1 {
            "byte"
        } else {
            "bytes"
        };
        write!(f, "{x}×{y}×{z} × {} {unit}", self.components)
    }
}

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
            dims: header.dims,
            components: header.components,
            expected,
            actual: available as u64,
        });
    }
    if expected > u128::from(max_voxel_bytes) {
        return Err(PvmError::TooLarge {
            dims: header.dims,
            components: header.components,
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

/// Allocation that reports failure instead of aborting.
fn try_with_capacity<T>(n: usize) -> Result<Vec<T>, PvmError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| PvmError::OutOfMemory((n as u64).saturating_mul(size_of::<T>() as u64)))?;
    Ok(v)
}

fn zeroed<T: Copy + Default>(n: usize) -> Result<Vec<T>, PvmError> {
    let mut v = try_with_capacity(n)?;
    v.resize(n, T::default());
    Ok(v)
}

fn copy_bytes(bytes: &[u8]) -> Result<Vec<u8>, PvmError> {
    let mut v = try_with_capacity(bytes.len())?;
    v.extend_from_slice(bytes);
    Ok(v)
}

/// Big-endian byte pairs → native `u16` (an odd last byte cannot occur: the length is 2·n).
fn u16_from_be(bytes: &[u8]) -> Result<Vec<u16>, PvmError> {
    let (pairs, _) = bytes.as_chunks::<2>();
    let mut v = try_with_capacity(pairs.len())?;
    v.extend(pairs.iter().map(|&p| u16::from_be_bytes(p)));
    Ok(v)
}

// ---------------------------------------------------------------------------------------
// DDS decompression (libmini readDDSfile / DDS_decode / DDS_interleave)
// ---------------------------------------------------------------------------------------

/// How a decoded DDS stream is split into byte planes (the layout `DDS_deinterleave`
/// produced and `DDS_interleave` undoes). File bytes are grouped into regions of
/// `block_bytes` (v3e: `skip × 2^24`; 0 for v3d: one region spanning the stream); inside
/// a region of length L the bytes at offsets ≡ c (mod skip) are stored together, plane
/// after plane. Only offsets are computed here: the planar buffer is never reshuffled.
#[derive(Debug, Clone, Copy)]
struct Planes {
    skip: usize,
    block_bytes: usize,
    len: usize,
}

impl Planes {
    /// Region containing file position `pos`: (start, length).
    fn region(&self, pos: usize) -> (usize, usize) {
        let block = if self.block_bytes == 0 {
            self.len
        } else {
            self.block_bytes
        };
        if block == 0 {
            return (0, 0);
        }
        let base = pos / block * block;
        (base, block.min(self.len.saturating_sub(base)))
    }

    /// Offset inside a region of length `region_len` where plane `c` starts: the number
    /// of positions ≡ 0, 1, …, c−1 (mod skip) in the region.
    fn plane_start(&self, region_len: usize, c: usize) -> usize {
        (0..c)
            .map(|k| (region_len + self.skip - 1 - k) / self.skip)
            .sum()
    }

    /// Index in the planar buffer of file byte `pos`.
    fn index(&self, pos: usize) -> usize {
        if self.skip <= 1 {
            return pos;
        }
        let (base, region_len) = self.region(pos);
        let r = pos - base;
        base + self.plane_start(region_len, r % self.skip) + r / self.skip
    }

    /// Calls `put(pos − start, byte)` for every file position `pos` in `start..end`,
    /// walking each plane sequentially (no division per byte).
    fn gather(&self, planar: &[u8], start: usize, end: usize, mut put: impl FnMut(usize, u8)) {
        let end = end.min(self.len);
        let skip = self.skip.max(1);
        let mut pos = start;
        while pos < end {
            let (base, region_len) = self.region(pos);
            if region_len == 0 {
                break;
            }
            let region_end = base + region_len;
            let stop = end.min(region_end);
            let first = pos - base; // first wanted offset inside the region
            for c in 0..skip {
                // First offset ≥ `first` in plane c.
                let r0 = if first <= c {
                    c
                } else {
                    c + (first - c).div_ceil(skip) * skip
                };
                let mut offset = r0;
                let mut idx = base + self.plane_start(region_len, c) + r0 / skip;
                while base + offset < stop {
                    if let Some(&b) = planar.get(idx) {
                        put(base + offset - start, b);
                    }
                    offset += skip;
                    idx += 1;
                }
            }
            pos = stop;
        }
    }
}

/// MSB-first bit reader over the DDS stream. Reads past the end return zeros, as
/// libmini's `DDS_loadbits`/`DDS_readbits` pad the stream with zero words.
struct BitReader<'a> {
    bytes: &'a [u8],
    /// Bit position of the next read.
    pos: u64,
}

impl<'a> BitReader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, pos: 0 }
    }

    fn end(&self) -> u64 {
        self.bytes.len() as u64 * 8
    }

    fn past_end(&self) -> bool {
        self.pos > self.end()
    }

    /// The next `n ≤ 16` bits as an unsigned number.
    #[inline]
    fn read(&mut self, n: u32) -> u32 {
        debug_assert!(n <= 16);
        let byte = usize::try_from(self.pos >> 3).unwrap_or(usize::MAX);
        let at = |i: usize| u32::from(self.bytes.get(byte.saturating_add(i)).copied().unwrap_or(0));
        let window = (at(0) << 16) | (at(1) << 8) | at(2);
        let shift = 24 - (self.pos & 7) as u32 - n;
        self.pos += u64::from(n);
        (window >> shift) & ((1u32 << n) - 1)
    }

    fn skip(&mut self, n: u64) {
        self.pos = self.pos.saturating_add(n);
    }
}

/// The 18-bit header of a DDS stream (the first two reads of libmini `DDS_decode`).
#[derive(Debug, Clone, Copy)]
struct DdsParams {
    /// Number of byte planes (1‥4).
    skip: usize,
    /// Row length used by the 2-D predictor (1‥65536; 1 disables it).
    strip: usize,
}

fn read_dds_params(reader: &mut BitReader<'_>) -> Result<DdsParams, PvmError> {
    let skip = reader.read(2) as usize + 1;
    let strip = reader.read(16) as usize + 1;
    if reader.past_end() {
        return Err(PvmError::CorruptDds(format!(
            "{} bytes are too short for the 18-bit stream header",
            reader.bytes.len()
        )));
    }
    Ok(DdsParams { skip, strip })
}

/// Width in bits of a run's values from its 3-bit code (libmini `DDS_decode(int)`):
/// 0 → 0, k → k + 1, so widths are 0, 2, 3, …, 8.
fn value_width(code: u32) -> u32 {
    if code == 0 { 0 } else { code + 1 }
}

/// The error for a run that reaches past the end of the data (a truncated file, mostly).
fn overrun(reader: &BitReader<'_>, run_start: u64) -> PvmError {
    PvmError::CorruptDds(format!(
        "the data ends inside a run (bits {run_start}‥{} needed, {} present; the file is probably truncated)",
        reader.pos,
        reader.end()
    ))
}

/// First pass over a DDS stream: how many bytes it decodes to, storing nothing. Each
/// run consumes at least 10 bits, and a run reaching past the data is an error, so
/// this ends after at most `stream.len() · 8 / 10` runs.
fn dds_decoded_len(stream: &[u8]) -> Result<(DdsParams, u64), PvmError> {
    let mut reader = BitReader::new(stream);
    let params = read_dds_params(&mut reader)?;
    let mut total = 0u64;
    loop {
        let run_start = reader.pos;
        let count = reader.read(DDS_RUN_BITS);
        if count == 0 {
            break;
        }
        let width = value_width(reader.read(3));
        reader.skip(u64::from(count) * u64::from(width));
        if reader.past_end() {
            return Err(overrun(&reader, run_start));
        }
        total += u64::from(count);
    }
    Ok((params, total))
}

/// Decodes the stream's bytes in planar order (libmini `DDS_decode` minus the final
/// `DDS_interleave`), handing each to `sink` with its index; stops early when `sink`
/// returns `false`. The 2-D predictor looks back `strip + 1` bytes, so a ring buffer
/// of the recent output suffices and the caller decides what to keep.
fn dds_decode_with(stream: &[u8], mut sink: impl FnMut(usize, u8) -> bool) -> Result<(), PvmError> {
    const RING: usize = 1 << 17; // > 65536 + 1, the largest look-back
    const MASK: usize = RING - 1;
    let mut ring = vec![0u8; RING];
    let mut reader = BitReader::new(stream);
    let params = read_dds_params(&mut reader)?;
    let strip = params.strip;
    let mut i = 0usize; // index of the next output byte
    let mut act: i32 = 0; // previous output byte
    loop {
        let run_start = reader.pos;
        let count = reader.read(DDS_RUN_BITS);
        if count == 0 {
            return Ok(());
        }
        let width = value_width(reader.read(3));
        let half = (1i32 << width) >> 1;
        for _ in 0..count {
            let delta = reader.read(width) as i32 - half;
            let predicted = if strip > 1 && i > strip {
                let a = ring.get((i - strip) & MASK).copied().unwrap_or(0);
                let b = ring.get((i - strip - 1) & MASK).copied().unwrap_or(0);
                i32::from(a) - i32::from(b)
            } else {
                0
            };
            act = (act + predicted + delta).rem_euclid(256);
            let byte = act as u8;
            if let Some(slot) = ring.get_mut(i & MASK) {
                *slot = byte;
            }
            if !sink(i, byte) {
                return Ok(());
            }
            i += 1;
        }
        if reader.past_end() {
            return Err(overrun(&reader, run_start));
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
                    dims: header.dims,
                    components: header.components,
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
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The first bytes of the Volume Library's Bucky.pvm (DDS v3d, skip 1, strip 32),
    /// as written by libmini's encoder: a golden sample of the real bit stream.
    const BUCKY_PREFIX: [u8; 56] = [
        0x44, 0x44, 0x53, 0x20, 0x76, 0x33, 0x64, 0x0a, 0x00, 0x07, 0xcb, 0xfd, 0x08, 0x67, 0x76,
        0x65, 0x7a, 0x97, 0xf6, 0xe9, 0x37, 0xf6, 0xe9, 0x37, 0xf5, 0x8a, 0x76, 0xf9, 0x16, 0xf9,
        0x15, 0x9a, 0x75, 0x97, 0x72, 0x1a, 0x04, 0x08, 0x10, 0x61, 0x45, 0x9b, 0x73, 0x56, 0x05,
        0x29, 0x23, 0xe8, 0x5b, 0xd0, 0x87, 0xf0, 0x48, 0x6a, 0xca, 0x28,
    ];

    /// Tiny xorshift64 PRNG so the tests need no crates.
    struct XorShift(u64);

    impl XorShift {
        fn next(&mut self) -> u64 {
            let mut x = self.0;
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            self.0 = x;
            x
        }

        fn below(&mut self, n: usize) -> usize {
            if n == 0 {
                0
            } else {
                (self.next() % n as u64) as usize
            }
        }
    }

    /// MSB-first bit writer for the test encoder.
    #[derive(Default)]
    struct BitWriter {
        bytes: Vec<u8>,
        acc: u64,
        bits: u32,
    }

    impl BitWriter {
        fn put(&mut self, value: u32, n: u32) {
            for k in (0..n).rev() {
                self.acc = (self.acc << 1) | u64::from((value >> k) & 1);
                self.bits += 1;
                if self.bits == 8 {
                    self.bytes.push(self.acc as u8);
                    self.acc = 0;
                    self.bits = 0;
                }
            }
        }

        fn finish(mut self) -> Vec<u8> {
            if self.bits > 0 {
                self.bytes.push((self.acc << (8 - self.bits)) as u8);
            }
            self.bytes
        }
    }

    /// A simple but valid DDS encoder (not libmini's run merging): split into planes as
    /// `DDS_deinterleave` does, predict, and emit runs of ≤ 127 values at the widest
    /// width any of them needs. `block_elems` 0 = v3d layout. `terminator` writes an
    /// explicit zero count (libmini relies on the zero padding instead).
    fn dds_encode(
        data: &[u8],
        skip: usize,
        strip: usize,
        block_elems: usize,
        terminator: bool,
    ) -> Vec<u8> {
        let planes = Planes {
            skip,
            block_bytes: if block_elems == 0 {
                0
            } else {
                block_elems * skip
            },
            len: data.len(),
        };
        let mut planar = vec![0u8; data.len()];
        for (pos, &b) in data.iter().enumerate() {
            planar[planes.index(pos)] = b;
        }
        let mut deltas = Vec::with_capacity(planar.len());
        let mut prev = 0i32;
        for i in 0..planar.len() {
            let pred = if strip > 1 && i > strip {
                i32::from(planar[i - strip]) - i32::from(planar[i - strip - 1])
            } else {
                0
            };
            let d = (i32::from(planar[i]) - prev - pred).rem_euclid(256);
            deltas.push(if d > 127 { d - 256 } else { d });
            prev = i32::from(planar[i]);
        }
        let width_of = |d: i32| -> u32 {
            if d == 0 {
                return 0;
            }
            (2..=8)
                .find(|&w| -(1 << w) / 2 <= d && d < (1 << w) / 2)
                .unwrap()
        };
        let mut w = BitWriter::default();
        w.put(skip as u32 - 1, 2);
        w.put(strip as u32 - 1, 16);
        for run in deltas.chunks(127) {
            let width = run.iter().map(|&d| width_of(d)).max().unwrap();
            w.put(run.len() as u32, 7);
            w.put(if width == 0 { 0 } else { width - 1 }, 3);
            for &d in run {
                w.put((d + (1 << width) / 2) as u32, width);
            }
        }
        if terminator {
            w.put(0, 7);
        }
        w.finish()
    }

    fn with_magic(magic: &[u8], stream: &[u8]) -> Vec<u8> {
        [magic, stream].concat()
    }

    fn write_to_vec(
        dims: [usize; 3],
        spacing: [f32; 3],
        voxels: &PvmVoxels,
        descriptions: &[(String, String)],
    ) -> Vec<u8> {
        let mut out = Vec::new();
        write_pvm3(&mut out, dims, spacing, voxels.samples(), descriptions).unwrap();
        out
    }

    fn descs(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(l, t)| (l.to_string(), t.to_string()))
            .collect()
    }

    const MB: u64 = 1 << 20;

    #[test]
    fn roundtrip_u8_odd_dims() {
        let dims = [3, 5, 7];
        let voxels = PvmVoxels::U8((0..105u32).map(|i| (i * 37 % 256) as u8).collect());
        let d = descs(&[
            ("description", "Test volume"),
            ("courtesy", "nobody"),
            ("parameter", "x=1"),
            ("comment", "multi\nline ünïcode"),
        ]);
        let bytes = write_to_vec(dims, [1.0, 0.5, 1.4], &voxels, &d);
        assert!(bytes.starts_with(b"PVM3\n3 5 7\n1 0.5 1.4\n1\n"));
        let v = read_pvm(&bytes, MB).unwrap();
        assert_eq!(v.dims, dims);
        assert_eq!(v.spacing, Some([1.0, 0.5, 1.4]));
        assert_eq!(v.voxels, voxels);
        assert_eq!(v.descriptions, d);
        assert_eq!(v.version, PvmVersion::Pvm3);
        assert_eq!(v.compression, None);
    }

    #[test]
    fn roundtrip_u16_big_endian() {
        let dims = [3, 5, 7];
        let mut values: Vec<u16> = (0..105u32).map(|i| (i * 2477 % 65536) as u16).collect();
        values[0] = 0x1234;
        values[1] = 0xffff;
        values[2] = 0;
        let voxels = PvmVoxels::U16(values);
        let d = descs(&[("courtesy", "c"), ("comment", "")]);
        let bytes = write_to_vec(dims, [0.1, 3.333_333_3, 1e-7], &voxels, &d);
        let header = b"PVM3\n3 5 7\n0.1 3.3333333 0.0000001\n2\n";
        assert!(bytes.starts_with(header), "{:?}", show(&bytes));
        assert_eq!(
            &bytes[header.len()..header.len() + 4],
            &[0x12, 0x34, 0xff, 0xff]
        );
        assert!(bytes.ends_with(b"\0c\0\0\0"));
        let v = read_pvm(&bytes, MB).unwrap();
        assert_eq!(v.voxels, voxels);
        assert_eq!(v.spacing, Some([0.1, 3.333_333_3, 1e-7]));
        assert_eq!(v.descriptions, descs(&[("courtesy", "c")]));
    }

    #[test]
    fn writer_merges_unknown_labels_and_rejects_bad_input() {
        let voxels = PvmVoxels::U8(vec![1, 2]);
        let d = descs(&[("descrip", "from nifti"), ("Comment", "hello")]);
        let v = read_pvm(&write_to_vec([2, 1, 1], [1.0; 3], &voxels, &d), MB).unwrap();
        assert_eq!(
            v.descriptions,
            descs(&[("comment", "descrip: from nifti\nhello")])
        );

        let mut sink = Vec::new();
        assert!(write_pvm3(&mut sink, [0, 1, 2], [1.0; 3], voxels.samples(), &[]).is_err());
        assert!(write_pvm3(&mut sink, [3, 1, 1], [1.0; 3], voxels.samples(), &[]).is_err());
        assert!(write_pvm3(&mut sink, [2, 1, 1], [0.0, 1.0, 1.0], voxels.samples(), &[]).is_err());
        assert!(
            write_pvm3(
                &mut sink,
                [2, 1, 1],
                [f32::NAN, 1.0, 1.0],
                voxels.samples(),
                &[]
            )
            .is_err()
        );
        let nul = descs(&[("comment", "a\0b")]);
        assert!(write_pvm3(&mut sink, [2, 1, 1], [1.0; 3], voxels.samples(), &nul).is_err());
    }

    #[test]
    fn plain_pvm1_with_comments() {
        let bytes = b"PVM\n# a comment\n#another\n2 2 1\n1\n\x01\x02\x03\x04";
        let v = read_pvm(bytes, MB).unwrap();
        assert_eq!(v.version, PvmVersion::Pvm1);
        assert_eq!(v.dims, [2, 2, 1]);
        assert_eq!(v.spacing, None);
        assert_eq!(v.voxels, PvmVoxels::U8(vec![1, 2, 3, 4]));
        assert!(v.descriptions.is_empty());
    }

    #[test]
    fn pvm2_sixteen_bit() {
        let bytes = b"PVM2\n2 1 1\n0.5 1 2\n2\n\x01\x02\xff\xfe";
        let v = read_pvm(bytes, MB).unwrap();
        assert_eq!(v.version, PvmVersion::Pvm2);
        assert_eq!(v.spacing, Some([0.5, 1.0, 2.0]));
        assert_eq!(v.voxels, PvmVoxels::U16(vec![0x0102, 0xfffe]));
        // CRLF line ends are tolerated.
        let crlf = b"PVM2\r\n2 1 1\r\n0.5 1 2\r\n2\r\n\x01\x02\xff\xfe";
        assert_eq!(read_pvm(crlf, MB).unwrap().voxels, v.voxels);
    }

    #[test]
    fn header_errors() {
        let err = |b: &[u8]| read_pvm(b, MB).unwrap_err();
        assert!(matches!(err(b"GIF89a"), PvmError::NotPvm { .. }));
        assert!(matches!(
            err(b"PVMS\n1 1 1\n1\n\0"),
            PvmError::UnsupportedVariant(_)
        ));
        assert!(matches!(err(b"PVM\n0 2 2\n1\n"), PvmError::ZeroDims { .. }));
        assert!(matches!(
            err(b"PVM\n2 2 2\n3\n12345678"),
            PvmError::UnsupportedComponents(3)
        ));
        assert!(matches!(
            err(b"PVM\n2 2 2\n0\n"),
            PvmError::UnsupportedComponents(0)
        ));
        assert!(matches!(err(b"PVM\n2 -2 2\n1\n"), PvmError::BadHeader(_)));
        assert!(matches!(err(b"PVM\n2 2\n1\n"), PvmError::BadHeader(_)));
        assert!(matches!(err(b"PVM\n2 2 2 2\n1\n"), PvmError::BadHeader(_)));
        assert!(matches!(
            err(b"PVM\n9999999999 2 2\n1\n"),
            PvmError::BadHeader(_)
        ));
        for spacing in ["0 1 1", "1 -1 1", "nan 1 1", "1 inf 1", "1 1 1e39"] {
            let b = format!("PVM2\n1 1 1\n{spacing}\n1\n\x07");
            assert!(
                matches!(err(b.as_bytes()), PvmError::BadSpacing { .. }),
                "{spacing}"
            );
        }
        assert!(matches!(
            err(b"PVM\n1 1 1\n1\n\x07\x08"),
            PvmError::TrailingBytes { count: 1, .. }
        ));
        assert!(matches!(
            err(b"PVM3\n1 1 1\n1 1 1\n1\n\x07a\0b\0c\0"),
            PvmError::TruncatedStrings(_)
        ));
        assert!(matches!(
            err(b"PVM3\n1 1 1\n1 1 1\n1\n\x07\0\0\0\0x"),
            PvmError::TrailingBytes { .. }
        ));
    }

    #[test]
    fn truncation_is_an_error_with_sizes() {
        let voxels = PvmVoxels::U8(vec![9; 105]);
        let full = write_to_vec([3, 5, 7], [1.0; 3], &voxels, &descs(&[("comment", "x")]));
        for cut in 0..full.len() {
            assert!(
                read_pvm(&full[..cut], MB).is_err(),
                "prefix of {cut} bytes was accepted"
            );
        }
        let header_len = b"PVM3\n3 5 7\n1 1 1\n1\n".len();
        let msg = read_pvm(&full[..header_len + 50], MB)
            .unwrap_err()
            .to_string();
        assert_eq!(
            msg,
            "truncated: header says 3×5×7 × 1 byte = 105 bytes of voxels but only 50 follow"
        );
        let msg = read_pvm(b"PVM3\n3 5 7\n1 1", MB).unwrap_err().to_string();
        assert!(msg.starts_with("truncated:"), "{msg}");
    }

    #[test]
    fn absurd_dims_refused_without_allocating() {
        let mut b = b"PVM3\n65535 65535 65535\n1 1 1\n2\n".to_vec();
        b.extend_from_slice(&[0; 100]);
        let e = read_pvm(&b, MB).unwrap_err();
        assert!(
            matches!(
                e,
                PvmError::Truncated {
                    expected: 562_924_184_010_750,
                    ..
                }
            ),
            "{e}"
        );
        // A complete file that is merely over the caller's limit.
        let ok = write_to_vec([3, 5, 7], [1.0; 3], &PvmVoxels::U8(vec![0; 105]), &[]);
        assert!(matches!(
            read_pvm(&ok, 104),
            Err(PvmError::TooLarge {
                bytes: 105,
                limit: 104,
                ..
            })
        ));
        assert!(read_pvm(&ok, 105).is_ok());
        // A DDS stream whose header claims absurd dims: refused from the header alone.
        let mut absurd = b"PVM3\n65535 65535 65535\n1 1 1\n2\n".to_vec();
        absurd.extend_from_slice(&[0; 64]);
        let e = read_pvm(
            &with_magic(DDS_V3D_MAGIC, &dds_encode(&absurd, 1, 1, 0, true)),
            MB,
        )
        .unwrap_err();
        assert!(matches!(e, PvmError::Truncated { .. }), "{e}");
    }

    #[test]
    fn dds_stream_over_the_limit_is_refused_before_decoding() {
        // 2 MiB of zeros compresses to a few KiB; with a 1 KiB cap it must be refused.
        let dims = [128, 128, 128];
        let file = write_to_vec(
            dims,
            [1.0; 3],
            &PvmVoxels::U8(vec![0; 128 * 128 * 128]),
            &[],
        );
        for skip in [1, 2] {
            let dds = with_magic(DDS_V3D_MAGIC, &dds_encode(&file, skip, 128, 0, false));
            let e = read_pvm(&dds, 1024).unwrap_err();
            assert!(
                matches!(
                    e,
                    PvmError::TooLarge {
                        bytes: 2_097_152,
                        limit: 1024,
                        ..
                    }
                ),
                "{e}"
            );
        }
        // Garbage that decodes to a long non-PVM stream: counted, never stored.
        let ones = with_magic(DDS_V3D_MAGIC, &vec![0xff; 1 << 16]);
        assert!(read_pvm(&ones, 1024).is_err());
    }

    #[test]
    fn golden_prefix_of_a_real_file_decodes_to_its_header() {
        let stream = &BUCKY_PREFIX[DDS_V3D_MAGIC.len()..];
        let mut reader = BitReader::new(stream);
        let params = read_dds_params(&mut reader).unwrap();
        assert_eq!((params.skip, params.strip), (1, 32));
        let planes = Planes {
            skip: 1,
            block_bytes: 0,
            len: 22,
        };
        let header = dds_peek(stream, planes, 22).unwrap().unwrap();
        assert_eq!(header, b"PVM3\n32 32 32\n1 1 1\n1\n");
        // The prefix alone is a truncated stream: an error, not a panic.
        assert!(matches!(
            read_pvm(&BUCKY_PREFIX, MB),
            Err(PvmError::CorruptDds(_))
        ));
    }

    fn sample_file(two_bytes: bool) -> (Vec<u8>, PvmVoxels) {
        let dims = [13, 6, 5];
        let n = 13 * 6 * 5;
        let voxels = if two_bytes {
            PvmVoxels::U16(
                (0..n as u32)
                    .map(|i| ((i * i * 97 + i * 13) % 65536) as u16)
                    .collect(),
            )
        } else {
            PvmVoxels::U8(
                (0..n as u32)
                    .map(|i| ((i % 13) * 11 + (i / 78) * 7) as u8)
                    .collect(),
            )
        };
        let d = descs(&[("description", "sample"), ("parameter", "p")]);
        (write_to_vec(dims, [1.0, 2.0, 3.0], &voxels, &d), voxels)
    }

    #[test]
    fn dds_v3d_roundtrips_through_our_encoder() {
        for two in [false, true] {
            let (file, voxels) = sample_file(two);
            for skip in [1, 2, 3, 4] {
                for strip in [1, 2, 13, 26] {
                    for terminator in [false, true] {
                        let dds = with_magic(
                            DDS_V3D_MAGIC,
                            &dds_encode(&file, skip, strip, 0, terminator),
                        );
                        let v = read_pvm(&dds, MB).unwrap();
                        assert_eq!(v.voxels, voxels, "skip {skip} strip {strip}");
                        assert_eq!(v.compression, Some(DdsVersion::V3d));
                        assert_eq!(
                            v.descriptions,
                            descs(&[("description", "sample"), ("parameter", "p")])
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn dds_v3e_blocks_with_a_small_block_size() {
        // The real v3e block is skip × 2^24 bytes; the layout logic is the same for any
        // block, so test it with tiny blocks that split the file into many regions.
        for two in [false, true] {
            let (file, voxels) = sample_file(two);
            for skip in [1, 2, 3] {
                for block in [1, 7, 64, 1000] {
                    let stream = dds_encode(&file, skip, 13, block, false);
                    let source = decompress_dds(&stream, block, MB).unwrap();
                    let v = parse_pvm(source, Some(DdsVersion::V3e), MB).unwrap();
                    assert_eq!(v.voxels, voxels, "skip {skip} block {block}");
                }
            }
            // And through the public entry point with the real block size.
            let dds = with_magic(
                DDS_V3E_MAGIC,
                &dds_encode(&file, 2, 13, V3E_INTERLEAVE_BLOCK, false),
            );
            let v = read_pvm(&dds, MB).unwrap();
            assert_eq!((v.voxels, v.compression), (voxels, Some(DdsVersion::V3e)));
        }
    }

    #[test]
    fn planes_gather_matches_index() {
        let mut rng = XorShift(7);
        for _ in 0..200 {
            let len = rng.below(300) + 1;
            let skip = rng.below(4) + 1;
            let block_bytes = if rng.below(2) == 0 {
                0
            } else {
                (rng.below(40) + 1) * skip
            };
            let planes = Planes {
                skip,
                block_bytes,
                len,
            };
            let planar: Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
            let start = rng.below(len);
            let end = start + rng.below(len - start + 1);
            let mut got = vec![None; end - start];
            planes.gather(&planar, start, end, |i, b| got[i] = Some(b));
            for (k, g) in got.iter().enumerate() {
                assert_eq!(*g, Some(planar[planes.index(start + k)]));
            }
            let mut seen = vec![false; len];
            for pos in 0..len {
                seen[planes.index(pos)] = true;
            }
            assert!(seen.iter().all(|&s| s), "index is not a permutation");
        }
    }

    fn mutate(rng: &mut XorShift, base: &[u8]) -> Vec<u8> {
        let mut m = base.to_vec();
        for _ in 0..=rng.below(3) {
            match rng.below(6) {
                0 => m.truncate(rng.below(m.len() + 1)),
                1 => {
                    let i = rng.below(m.len());
                    if let Some(b) = m.get_mut(i) {
                        *b ^= 1 << rng.below(8);
                    }
                }
                2 => {
                    let i = rng.below(m.len());
                    if let Some(b) = m.get_mut(i) {
                        *b = rng.next() as u8;
                    }
                }
                3 => {
                    let i = rng.below(m.len() + 1);
                    let pick = b"0123456789 \n#-.e\0\xff";
                    m.insert(i, pick[rng.below(pick.len())]);
                }
                4 => {
                    if !m.is_empty() {
                        m.remove(rng.below(m.len()));
                    }
                }
                _ => {
                    let i = rng.below(m.len() + 1);
                    m.extend_from_within(..i);
                }
            }
        }
        m
    }

    #[test]
    fn random_mutations_never_panic() {
        let (plain8, _) = sample_file(false);
        let (plain16, _) = sample_file(true);
        let corpus = vec![
            plain8.clone(),
            plain16.clone(),
            b"PVM\n# c\n2 2 1\n1\n\x01\x02\x03\x04".to_vec(),
            b"PVM2\n2 1 1\n0.5 1 2\n2\n\x01\x02\xff\xfe".to_vec(),
            BUCKY_PREFIX.to_vec(),
            with_magic(DDS_V3D_MAGIC, &dds_encode(&plain8, 1, 13, 0, false)),
            with_magic(DDS_V3D_MAGIC, &dds_encode(&plain16, 2, 13, 0, false)),
            with_magic(
                DDS_V3E_MAGIC,
                &dds_encode(&plain16, 2, 1, V3E_INTERLEAVE_BLOCK, true),
            ),
            with_magic(DDS_V3D_MAGIC, &dds_encode(&plain8, 3, 2, 0, true)),
        ];
        let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
        let mut accepted = 0;
        for round in 0..2400 {
            let base = &corpus[round % corpus.len()];
            let m = mutate(&mut rng, base);
            let limit = if rng.below(4) == 0 {
                rng.below(4096) as u64
            } else {
                MB
            };
            if let Ok(v) = read_pvm(&m, limit) {
                accepted += 1;
                assert_eq!(v.voxels.len(), v.dims.iter().product::<usize>());
                assert!(v.voxels.len() * v.voxels.bytes_per_voxel() <= limit as usize);
            }
        }
        assert!(
            accepted > 0,
            "no mutation survived; the corpus is not exercising the happy path"
        );
    }
}
