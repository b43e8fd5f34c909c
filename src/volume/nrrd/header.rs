//! The NRRD header: fields, types, encodings, space and per-axis lists, parsed from the
//! text before the blank line (or a detached `.nhdr`).

use crate::volume::{VolumeError, VoxelType, short_name};
use std::path::Path;

/// Longest header we read (a `LIST` of many slice files can be long, but not this long).
pub(super) const MAX_HEADER: u64 = 16 << 20;

/// How the voxel bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    Raw,
    Gzip,
    Ascii,
    Hex,
}

/// The world frame named by `space:`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Space {
    Ras,
    Las,
    Lps,
    /// scanner-xyz, 3D-right-handed, 3D-left-handed: no anatomical meaning.
    Other,
}

/// Every header field volao uses.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub ty: VoxelType,
    pub sizes: Vec<usize>,
    pub encoding: Encoding,
    pub little_endian: bool,
    pub space: Option<(Space, String)>,
    /// One entry per axis: `None` for `none` (a non-spatial axis).
    pub directions: Vec<Option<[f64; 3]>>,
    pub origin: Option<[f64; 3]>,
    pub spacings: Vec<f64>,
    pub kinds: Vec<String>,
    pub data_files: Vec<String>,
    pub line_skip: u64,
    /// `-1`: the voxels are the last bytes of the file (raw only).
    pub byte_skip: i64,
    pub content: Option<String>,
    /// `key:=value` pairs in header order (3D Slicer's `SegmentN_Name`, …), unescaped.
    pub key_values: Vec<(String, String)>,
    /// Bytes of the header including the blank line that ends it (attached data).
    pub header_len: u64,
}

/// Where the voxels of a parsed header are: the 3 spatial dims and the frame axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    pub dims: [usize; 3],
    /// Header axes (after dropping size-1 axes) that are x, y, z.
    pub axes: [Option<usize>; 3],
    pub frames: usize,
    pub frame_bytes: u64,
}

pub(super) fn invalid(path: &Path, m: impl Into<String>) -> VolumeError {
    VolumeError::invalid(path, m)
}

/// Type names as teem spells them.
/// Why a field's value was refused.
enum Refused {
    /// NRRD knows the value but volao does not read it: the whole message.
    Unsupported(String),
    /// Not a value of the field: what was expected.
    Unknown(&'static str),
}

/// A NRRD `type`, in any case.
fn parse_type(s: &str) -> Result<VoxelType, Refused> {
    let unsupported = |what| {
        Refused::Unsupported(format!(
            "NRRD type {s} ({what}) is not supported (int8 … int32, uint8 … uint32, float, double)"
        ))
    };
    Ok(match s.to_ascii_lowercase().as_str() {
        "signed char" | "int8" | "int8_t" => VoxelType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => VoxelType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            VoxelType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            VoxelType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => VoxelType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => VoxelType::U32,
        "float" => VoxelType::F32,
        "double" => VoxelType::F64,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t"
        | "ulonglong"
        | "unsigned long long"
        | "unsigned long long int"
        | "uint64"
        | "uint64_t" => return Err(unsupported("64-bit integer")),
        "block" => return Err(unsupported("block")),
        _ => return Err(Refused::Unknown("a NRRD type (int8 … double)")),
    })
}

/// A NRRD `encoding` (lower case).
fn parse_encoding(s: &str) -> Result<Encoding, Refused> {
    Ok(match s {
        "raw" => Encoding::Raw,
        "gz" | "gzip" => Encoding::Gzip,
        "txt" | "text" | "ascii" => Encoding::Ascii,
        "hex" => Encoding::Hex,
        "bz2" | "bzip2" | "zstd" => {
            return Err(Refused::Unsupported(format!(
                "NRRD encoding {s} is not supported (raw, gzip, ascii, hex); re-save with gzip"
            )));
        }
        _ => return Err(Refused::Unknown("an encoding (raw, gzip, ascii, hex)")),
    })
}

pub(super) fn parse_vector(s: &str) -> Option<[f64; 3]> {
    let inner = s.trim().strip_prefix('(')?.strip_suffix(')')?;
    let v: Vec<f64> = inner
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// Splits `space directions` into per-axis tokens: `(a,b,c)` or `none`.
pub(super) fn split_vectors(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut depth = 0;
    for c in s.chars() {
        match c {
            '(' => {
                depth += 1;
                cur.push(c);
            }
            ')' => {
                depth -= 1;
                cur.push(c);
            }
            c if c.is_whitespace() && depth == 0 => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
            c => cur.push(c),
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Parses the header text (everything before the blank line). `header_len` is recorded
/// by the caller. Errors name `path`.
pub fn parse_header(text: &str, path: &Path) -> Result<Header, VolumeError> {
    let mut lines = text.lines();
    let magic = lines.next().unwrap_or_default().trim_end();
    let version = magic
        .strip_prefix("NRRD000")
        .and_then(|v| v.parse::<u8>().ok());
    if !matches!(version, Some(1..=5)) {
        return Err(invalid(
            path,
            format!(
                "not a NRRD file (first line {} should be NRRD0001 … NRRD0005)",
                short_name(magic)
            ),
        ));
    }
    let mut ty = None;
    let mut dimension = None;
    let mut sizes = None;
    let mut encoding = None;
    let mut little_endian = None;
    let mut space = None;
    let mut space_dimension = None;
    let mut directions = None;
    let mut origin = None;
    let mut spacings = Vec::new();
    let mut kinds = Vec::new();
    let mut data_files = Vec::new();
    let mut line_skip = 0u64;
    let mut byte_skip = 0i64;
    let mut content = None;
    let mut key_values = Vec::new();
    let mut list_mode = false;
    for (i, raw_line) in lines.enumerate() {
        let lineno = i + 2;
        if list_mode {
            let f = raw_line.trim();
            if !f.is_empty() {
                data_files.push(f.to_owned());
            }
            continue;
        }
        let line = raw_line.trim_end();
        if line.starts_with('#') || line.is_empty() {
            continue;
        }
        // A key/value pair when `:=` comes before any `: ` (values may hold ": ").
        if let Some(kv) = line.find(":=")
            && line.find(": ").is_none_or(|f| kv < f)
        {
            key_values.push((
                unescape_key_value(&line[..kv]),
                unescape_key_value(&line[kv + 2..]),
            ));
            continue;
        }
        let Some((field, value)) = line.split_once(": ") else {
            return Err(invalid(
                path,
                format!(
                    "header line {lineno}: expected \"field: value\", found {}",
                    short_name(line)
                ),
            ));
        };
        let field = field.trim().to_ascii_lowercase();
        let value = value.trim();
        let bad = |what: &str| {
            invalid(
                path,
                format!(
                    "header line {lineno}: {field} {} is not {what}",
                    short_name(value)
                ),
            )
        };
        let refused = |r| match r {
            Refused::Unsupported(message) => VolumeError::unsupported(path, message),
            Refused::Unknown(what) => bad(what),
        };
        match field.as_str() {
            "type" => ty = Some(parse_type(value).map_err(refused)?),
            "dimension" => {
                dimension = Some(
                    value
                        .parse::<usize>()
                        .ok()
                        .filter(|d| (1..=16).contains(d))
                        .ok_or_else(|| bad("a dimension from 1 to 16"))?,
                )
            }
            "sizes" => {
                let v: Vec<usize> = value
                    .split_whitespace()
                    .map(|s| s.parse::<usize>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad("a list of whole numbers"))?;
                if v.contains(&0) {
                    return Err(bad("a list of sizes ≥ 1"));
                }
                sizes = Some(v);
            }
            "encoding" => {
                encoding = Some(parse_encoding(&value.to_ascii_lowercase()).map_err(refused)?)
            }
            "endian" => {
                little_endian = Some(match value.to_ascii_lowercase().as_str() {
                    "little" => true,
                    "big" => false,
                    _ => return Err(bad("little or big")),
                })
            }
            "space" => {
                let lower = value.to_ascii_lowercase();
                let s = match lower.as_str() {
                    "right-anterior-superior" | "ras" => Space::Ras,
                    "left-anterior-superior" | "las" => Space::Las,
                    "left-posterior-superior" | "lps" => Space::Lps,
                    "scanner-xyz" | "3d-right-handed" | "3d-left-handed" => Space::Other,
                    "right-anterior-superior-time"
                    | "rast"
                    | "left-anterior-superior-time"
                    | "last"
                    | "left-posterior-superior-time"
                    | "lpst"
                    | "scanner-xyz-time"
                    | "3d-right-handed-time"
                    | "3d-left-handed-time" => {
                        return Err(VolumeError::unsupported(
                            path,
                            format!(
                                "NRRD space {value} has a time axis in space: volao reads 3-D spaces only"
                            ),
                        ));
                    }
                    _ => return Err(bad("a known space (RAS, LAS, LPS, scanner-xyz, …)")),
                };
                space = Some((s, value.to_owned()));
                space_dimension = Some(3);
            }
            "space dimension" => {
                let d = value.parse::<usize>().map_err(|_| bad("a whole number"))?;
                if d != 3 {
                    return Err(VolumeError::unsupported(
                        path,
                        format!("NRRD space dimension {d}: volao reads 3-D spaces only"),
                    ));
                }
                space_dimension = Some(d);
            }
            "space directions" => {
                let v = split_vectors(value)
                    .iter()
                    .map(|t| {
                        if t == "none" {
                            Ok(None)
                        } else {
                            parse_vector(t).map(Some).ok_or(())
                        }
                    })
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|_| bad("a list of (x,y,z) vectors or none"))?;
                directions = Some(v);
            }
            "space origin" => {
                origin = Some(parse_vector(value).ok_or_else(|| bad("an (x,y,z) vector"))?)
            }
            "spacings" => {
                spacings = value
                    .split_whitespace()
                    .map(|s| {
                        if s.eq_ignore_ascii_case("nan") {
                            Ok(f64::NAN)
                        } else {
                            s.parse::<f64>()
                        }
                    })
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad("a list of numbers"))?;
            }
            "kinds" => kinds = value.split_whitespace().map(str::to_owned).collect(),
            "data file" | "datafile" => {
                let parts: Vec<&str> = value.split_whitespace().collect();
                if parts.first().is_some_and(|p| *p == "LIST") {
                    list_mode = true;
                } else if parts.len() >= 4 && parts[0].contains('%') {
                    let num = |s: &str| s.parse::<i64>().map_err(|_| bad("a pattern with numbers"));
                    let (min, max, step) = (num(parts[1])?, num(parts[2])?, num(parts[3])?);
                    if step == 0 || (max - min) / step < 0 || (max - min) / step > 1_000_000 {
                        return Err(bad("a pattern with a usable min, max and step"));
                    }
                    let mut k = min;
                    while (step > 0 && k <= max) || (step < 0 && k >= max) {
                        data_files.push(
                            sprintf_int(parts[0], k)
                                .ok_or_else(|| bad("a file pattern with one %d"))?,
                        );
                        k += step;
                    }
                } else {
                    data_files.push(value.to_owned());
                }
            }
            "line skip" | "lineskip" => {
                line_skip = value.parse().map_err(|_| bad("a line count"))?;
            }
            "byte skip" | "byteskip" => {
                byte_skip = value
                    .parse::<i64>()
                    .ok()
                    .filter(|b| *b >= -1)
                    .ok_or_else(|| bad("a byte count or -1"))?;
            }
            "content" => content = Some(value.to_owned()),
            _ => {}
        }
    }
    let missing = |f: &str| invalid(path, format!("the NRRD header has no {f:?} field"));
    let ty = ty.ok_or_else(|| missing("type"))?;
    let dimension = dimension.ok_or_else(|| missing("dimension"))?;
    let sizes = sizes.ok_or_else(|| missing("sizes"))?;
    let encoding = encoding.ok_or_else(|| missing("encoding"))?;
    if sizes.len() != dimension {
        return Err(invalid(
            path,
            format!(
                "dimension is {dimension} but sizes lists {} numbers",
                sizes.len()
            ),
        ));
    }
    let per_axis = |name: &str, n: usize| -> Result<(), VolumeError> {
        if n != 0 && n != dimension {
            Err(invalid(
                path,
                format!("{name} lists {n} axes but dimension is {dimension}"),
            ))
        } else {
            Ok(())
        }
    };
    per_axis("kinds", kinds.len())?;
    per_axis("spacings", spacings.len())?;
    let directions = directions.unwrap_or_default();
    per_axis("space directions", directions.len())?;
    if !directions.is_empty() && space_dimension.is_none() {
        return Err(invalid(
            path,
            "space directions given without space or space dimension",
        ));
    }
    if byte_skip == -1 && encoding != Encoding::Raw {
        return Err(invalid(
            path,
            "byte skip -1 (voxels at the end of the file) needs raw encoding",
        ));
    }
    let little_endian = match little_endian {
        Some(le) => le,
        None if ty.size() > 1
            && matches!(encoding, Encoding::Raw | Encoding::Gzip | Encoding::Hex) =>
        {
            return Err(missing("endian"));
        }
        None => true,
    };
    Ok(Header {
        ty,
        sizes,
        encoding,
        little_endian,
        space,
        directions,
        origin,
        spacings,
        kinds,
        data_files,
        line_skip,
        byte_skip,
        content,
        key_values,
        header_len: 0,
    })
}

/// A key or value of a `key:=value` pair with NRRD's escapes (`\n` newline, `\\`
/// backslash) undone.
fn unescape_key_value(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c != '\\' {
            out.push(c);
            continue;
        }
        match chars.next() {
            Some('n') => out.push('\n'),
            Some('\\') => out.push('\\'),
            Some(other) => {
                out.push('\\');
                out.push(other);
            }
            None => out.push('\\'),
        }
    }
    out
}

/// `slice%03d.raw` with 7 → `slice007.raw` (the only printf form teem's data-file
/// patterns use).
pub(super) fn sprintf_int(pattern: &str, k: i64) -> Option<String> {
    let start = pattern.find('%')?;
    let rest = &pattern[start + 1..];
    let end = rest.find(|c: char| !c.is_ascii_digit())?;
    if !rest[end..].starts_with(['d', 'i', 'u']) || rest[end + 1..].contains('%') {
        return None;
    }
    let spec = &rest[..end];
    let width: usize = if spec.is_empty() {
        0
    } else {
        spec.parse().ok()?
    };
    if width > 32 {
        return None;
    }
    let num = if spec.starts_with('0') {
        format!("{k:0width$}")
    } else {
        format!("{k:width$}")
    };
    Some(format!("{}{}{}", &pattern[..start], num, &rest[end + 1..]))
}

pub(super) const DOMAIN_KINDS: [&str; 3] = ["domain", "space", "time"];
