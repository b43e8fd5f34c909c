//! Headerless raw voxels described by command-line flags or by an Inviwo-style `.dat`
//! sidecar (`ObjectFileName`, `Resolution`, `SliceThickness`, `Format`, …).

use super::nifti::read_voxels;
use super::{Volume, VolumeError, VoxelType, check_spacing, fmt_bytes, fmt_dims, nifti::Layout};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Byte order of multi-byte voxels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Endian {
    #[default]
    Little,
    Big,
}

/// How to read a raw file: everything the file itself does not say.
#[derive(Debug, Clone, PartialEq)]
pub struct RawSpec {
    pub dims: [usize; 3],
    pub ty: VoxelType,
    pub endian: Endian,
    pub spacing: [f32; 3],
    /// Bytes to skip before the first voxel.
    pub offset: u64,
}

/// A raw spec given partly on the command line: each `Some` overrides the sidecar.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RawOverrides {
    pub dims: Option<[usize; 3]>,
    pub ty: Option<VoxelType>,
    pub endian: Option<Endian>,
    pub spacing: Option<[f32; 3]>,
    pub offset: Option<u64>,
}

impl RawOverrides {
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// What an Inviwo `.dat` sidecar says.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DatSidecar {
    pub object_file: Option<String>,
    pub dims: Option<[usize; 3]>,
    pub spacing: Option<[f32; 3]>,
    pub ty: Option<VoxelType>,
    pub endian: Option<Endian>,
    pub offset: Option<u64>,
}

/// Parses the text of an Inviwo `.dat` sidecar. Unknown keys are ignored; known keys
/// with unusable values are errors (message without the path; the caller adds it).
pub fn parse_dat(text: &str) -> Result<DatSidecar, String> {
    let mut dat = DatSidecar::default();
    for (lineno, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let Some((key, value)) = line.split_once(':') else {
            return Err(format!(
                "line {}: expected \"Key: value\", found {:?}",
                lineno + 1,
                truncate(line)
            ));
        };
        let (key, value) = (key.trim().to_ascii_lowercase(), value.trim());
        let err = |what: &str| {
            format!(
                "line {}: {key} {:?} is not {what}",
                lineno + 1,
                truncate(value)
            )
        };
        match key.as_str() {
            "objectfilename" | "rawfile" => {
                if value.is_empty() {
                    return Err(format!(
                        "line {}: {key} is empty: which file holds the voxels?",
                        lineno + 1
                    ));
                }
                dat.object_file = Some(value.to_owned());
            }
            "resolution" | "dimensions" => {
                let v = numbers::<usize>(value)
                    .filter(|v| v.len() == 3)
                    .ok_or_else(|| err("three whole numbers"))?;
                dat.dims = Some([v[0], v[1], v[2]]);
            }
            "slicethickness" | "spacing" => {
                let v = numbers::<f32>(value)
                    .filter(|v| v.len() == 3)
                    .ok_or_else(|| err("three numbers"))?;
                dat.spacing = Some([v[0], v[1], v[2]]);
            }
            "format" => {
                dat.ty = Some(dat_format(value).ok_or_else(|| {
                    err("a known format (UCHAR, CHAR, USHORT, SHORT, UINT, INT, FLOAT, DOUBLE)")
                })?)
            }
            "byteorder" => {
                dat.endian = Some(match value.to_ascii_lowercase().as_str() {
                    "littleendian" | "little" => Endian::Little,
                    "bigendian" | "big" => Endian::Big,
                    _ => return Err(err("LittleEndian or BigEndian")),
                })
            }
            "byteoffset" | "headeroffset" => {
                dat.offset = Some(value.parse().map_err(|_| err("a byte count"))?)
            }
            _ => {}
        }
    }
    Ok(dat)
}

fn truncate(s: &str) -> String {
    s.chars().take(40).collect()
}

fn numbers<T: std::str::FromStr>(s: &str) -> Option<Vec<T>> {
    s.split_whitespace().map(|t| t.parse().ok()).collect()
}

/// Inviwo/Voreen format names.
fn dat_format(name: &str) -> Option<VoxelType> {
    Some(match name.to_ascii_uppercase().as_str() {
        "UCHAR" | "UINT8" => VoxelType::U8,
        "CHAR" | "INT8" => VoxelType::I8,
        "USHORT" | "UINT16" => VoxelType::U16,
        "SHORT" | "INT16" => VoxelType::I16,
        "UINT" | "UINT32" => VoxelType::U32,
        "INT" | "INT32" => VoxelType::I32,
        "FLOAT" | "FLOAT32" => VoxelType::F32,
        "DOUBLE" | "FLOAT64" => VoxelType::F64,
        _ => return None,
    })
}

fn dat_format_name(ty: VoxelType) -> &'static str {
    match ty {
        VoxelType::U8 => "UCHAR",
        VoxelType::I8 => "CHAR",
        VoxelType::U16 => "USHORT",
        VoxelType::I16 => "SHORT",
        VoxelType::U32 => "UINT",
        VoxelType::I32 => "INT",
        VoxelType::F32 => "FLOAT",
        VoxelType::F64 => "DOUBLE",
    }
}

/// A description file beside a raw volume.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sidecar {
    /// Inviwo `.dat` text header.
    Dat(PathBuf),
    /// InVesalius project description (`main.plist` style, XML property list).
    Plist(PathBuf),
}

impl Sidecar {
    pub fn path(&self) -> &Path {
        match self {
            Sidecar::Dat(p) | Sidecar::Plist(p) => p,
        }
    }

    /// ".dat" or ".plist", for messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Sidecar::Dat(_) => ".dat",
            Sidecar::Plist(_) => ".plist",
        }
    }
}

/// The sidecar that describes `path`: the file itself if it is a `.dat`, else
/// `<stem>.dat` or `<stem>.plist` beside it if one exists.
pub fn find_sidecar(path: &Path) -> Option<Sidecar> {
    let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
    if ext == "dat" {
        return Some(Sidecar::Dat(path.to_owned()));
    }
    let dat = path.with_extension("dat");
    if dat.is_file() {
        return Some(Sidecar::Dat(dat));
    }
    let plist = path.with_extension("plist");
    plist.is_file().then_some(Sidecar::Plist(plist))
}

/// Reads the layout from an InVesalius plist: `matrix.dtype` (numpy name), `matrix.shape`
/// (z, y, x) and `spacing` (x, y, z). The voxels are little-endian, as InVesalius writes them.
pub fn parse_invesalius_plist(bytes: &[u8]) -> Result<DatSidecar, String> {
    let value = plist::Value::from_reader_xml(bytes)
        .map_err(|e| format!("not a readable XML plist ({e})"))?;
    let root = value
        .as_dictionary()
        .ok_or("plist root is not a dictionary")?;
    let matrix = root
        .get("matrix")
        .and_then(plist::Value::as_dictionary)
        .ok_or("plist has no 'matrix' dictionary (not an InVesalius project description)")?;
    let dtype = matrix
        .get("dtype")
        .and_then(plist::Value::as_string)
        .ok_or("matrix has no 'dtype'")?;
    let ty = match dtype {
        "uint8" => VoxelType::U8,
        "int8" => VoxelType::I8,
        "uint16" => VoxelType::U16,
        "int16" => VoxelType::I16,
        "uint32" => VoxelType::U32,
        "int32" => VoxelType::I32,
        "float32" => VoxelType::F32,
        "float64" => VoxelType::F64,
        other => return Err(format!("matrix dtype {other:?} is not supported")),
    };
    let numbers = |v: Option<&plist::Value>| -> Option<Vec<f64>> {
        v?.as_array()?
            .iter()
            .map(|x| {
                x.as_real()
                    .or_else(|| x.as_signed_integer().map(|i| i as f64))
            })
            .collect()
    };
    let shape = numbers(matrix.get("shape"))
        .filter(|s| s.len() == 3 && s.iter().all(|&d| d >= 1.0 && d.fract() == 0.0 && d < 1e9))
        .ok_or("matrix 'shape' is not three positive whole numbers")?;
    let spacing = numbers(root.get("spacing"))
        .filter(|s| s.len() == 3)
        .ok_or("plist 'spacing' is not three numbers")?;
    Ok(DatSidecar {
        object_file: None,
        dims: Some([shape[2] as usize, shape[1] as usize, shape[0] as usize]),
        spacing: Some([spacing[0] as f32, spacing[1] as f32, spacing[2] as f32]),
        ty: Some(ty),
        endian: Some(Endian::Little),
        offset: None,
    })
}

/// Works out the data file and full spec from the sidecar (if any) and the flags.
pub fn resolve(path: &Path, flags: &RawOverrides) -> Result<(PathBuf, RawSpec), VolumeError> {
    let mut dat = DatSidecar::default();
    let mut data_path = path.to_owned();
    match find_sidecar(path) {
        Some(Sidecar::Dat(side)) => {
            let text = read_small_text(&side)?;
            dat = parse_dat(&text).map_err(|m| VolumeError::invalid(&side, m))?;
            if side == path {
                let Some(obj) = &dat.object_file else {
                    return Err(VolumeError::invalid(
                        &side,
                        "sidecar has no ObjectFileName: which file holds the voxels?",
                    ));
                };
                data_path = side.parent().unwrap_or(Path::new(".")).join(obj);
            }
        }
        Some(Sidecar::Plist(side)) => {
            let bytes = read_small(&side)?;
            dat = parse_invesalius_plist(&bytes).map_err(|m| VolumeError::invalid(&side, m))?;
        }
        None => {}
    }
    let missing = |what: &str| {
        VolumeError::invalid(
            path,
            format!(
                "raw data needs {what}: pass --dims X Y Z --type TYPE (or put a .dat sidecar beside it)"
            ),
        )
    };
    let dims = flags
        .dims
        .or(dat.dims)
        .ok_or_else(|| missing("its dimensions"))?;
    let ty = flags
        .ty
        .or(dat.ty)
        .ok_or_else(|| missing("its voxel type"))?;
    let spacing = flags.spacing.or(dat.spacing).unwrap_or([1.0; 3]);
    check_spacing(spacing).map_err(|m| VolumeError::invalid(path, m))?;
    if dims.contains(&0) {
        return Err(VolumeError::invalid(
            path,
            format!("dimensions {} contain a zero", fmt_dims(dims)),
        ));
    }
    let spec = RawSpec {
        dims,
        ty,
        endian: flags.endian.or(dat.endian).unwrap_or_default(),
        spacing,
        offset: flags.offset.or(dat.offset).unwrap_or(0),
    };
    Ok((data_path, spec))
}

/// Reads a sidecar, refusing anything implausibly large for one.
fn read_small(path: &Path) -> Result<Vec<u8>, VolumeError> {
    let f = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut bytes = Vec::new();
    f.take(1 << 20)
        .read_to_end(&mut bytes)
        .map_err(|e| VolumeError::io(path, e))?;
    if bytes.len() >= 1 << 20 {
        return Err(VolumeError::invalid(
            path,
            "sidecar is over 1 MiB: not a text header",
        ));
    }
    Ok(bytes)
}

fn read_small_text(path: &Path) -> Result<String, VolumeError> {
    String::from_utf8(read_small(path)?)
        .map_err(|_| VolumeError::invalid(path, "sidecar is not UTF-8 text"))
}

/// Loads raw voxels as `spec` describes them.
pub fn load(
    path: &Path,
    spec: &RawSpec,
    max_bytes: u64,
    warnings: &mut Vec<String>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Volume, VolumeError> {
    let RawSpec {
        dims,
        ty,
        endian,
        spacing,
        offset,
    } = *spec;
    let frame_bytes = (dims[0] as u64)
        .checked_mul(dims[1] as u64)
        .and_then(|n| n.checked_mul(dims[2] as u64))
        .and_then(|n| n.checked_mul(ty.size() as u64))
        .filter(|&b| b <= max_bytes)
        .ok_or_else(|| VolumeError::TooLarge {
            path: path.to_owned(),
            dims: fmt_dims(dims),
            ty: ty.name().into(),
            bytes: dims
                .iter()
                .try_fold(ty.size() as u64, |a, &d| a.checked_mul(d as u64))
                .map_or("more than 2⁶⁴ bytes".into(), fmt_bytes),
            limit: fmt_bytes(max_bytes),
        })?;
    let mut file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let len = file.metadata().map_err(|e| VolumeError::io(path, e))?.len();
    let needed = offset.saturating_add(frame_bytes);
    let what = format!("{} {ty} voxels at offset {offset}", fmt_dims(dims));
    if len < needed {
        return Err(VolumeError::Truncated {
            path: path.to_owned(),
            what,
            expected: needed,
            actual: len,
        });
    }
    if len > needed {
        warnings.push(format!(
            "file has {} bytes more than {} {ty} voxels need; they are ignored (wrong --dims/--type/--offset?)",
            len - needed,
            fmt_dims(dims)
        ));
    }
    file.seek(SeekFrom::Start(offset))
        .map_err(|e| VolumeError::io(path, e))?;
    let lay = Layout {
        dims,
        ty,
        frame_bytes,
        frames: 1,
        vox_offset: offset,
    };
    // Voxels are read in large chunks straight into the buffer: no BufReader needed.
    let data = read_voxels(
        &mut file,
        &lay,
        endian == Endian::Little,
        path,
        offset,
        progress,
    )?;
    let mut v = Volume::new(dims, spacing, data).map_err(|m| VolumeError::invalid(path, m))?;
    v.scaling = super::Scaling::IDENTITY;
    Ok(v)
}

/// Writes little-endian raw voxels and an Inviwo `.dat` sidecar beside them
/// (`out.raw` + `out.dat`), so the file reopens without flags.
///
/// Raw has no scaling field: a volume with NIfTI scaling is written as f32 physical values.
pub fn save(
    volume: &Volume,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<PathBuf, VolumeError> {
    let physical;
    let data = if volume.scaling.is_identity() {
        &volume.data
    } else {
        warnings.push(format!(
            "raw has no scaling field: writing physical values (slope {} inter {}) as f32",
            volume.scaling.slope, volume.scaling.inter
        ));
        physical = super::VoxelData::F32(
            (0..volume.data.len())
                .map(|i| volume.scaling.apply(volume.data.get_f64(i)) as f32)
                .collect(),
        );
        &physical
    };
    let mut bytes_owned;
    let bytes = if cfg!(target_endian = "little") {
        data.as_bytes()
    } else {
        bytes_owned = data.clone();
        bytes_owned.swap_bytes();
        bytes_owned.as_bytes()
    };
    let mut f = std::fs::File::create(path).map_err(|e| VolumeError::io(path, e))?;
    f.write_all(bytes)
        .and_then(|_| f.flush())
        .map_err(|e| VolumeError::io(path, e))?;
    let dat_path = path.with_extension("dat");
    if dat_path == path {
        return Err(VolumeError::unsupported(
            path,
            "raw output must not end in .dat (that name is for the sidecar)",
        ));
    }
    let [nx, ny, nz] = volume.dims;
    let [sx, sy, sz] = volume.spacing;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let text = format!(
        "ObjectFileName:\t{name}\nResolution:\t{nx} {ny} {nz}\nSliceThickness:\t{sx} {sy} {sz}\nFormat:\t\t{}\nByteOrder:\tLittleEndian\n",
        dat_format_name(data.voxel_type())
    );
    std::fs::write(&dat_path, text).map_err(|e| VolumeError::io(&dat_path, e))?;
    Ok(dat_path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_inviwo_sidecars() {
        let d = parse_dat("ObjectFileName:\tengine.raw\nResolution:\t256 256 110\nSliceThickness:\t1 1 1\nFormat:\t\tUCHAR\n")
            .expect("valid sidecar");
        assert_eq!(d.object_file.as_deref(), Some("engine.raw"));
        assert_eq!(d.dims, Some([256, 256, 110]));
        assert_eq!(d.spacing, Some([1.0, 1.0, 1.0]));
        assert_eq!(d.ty, Some(VoxelType::U8));
        let d = parse_dat(
            "Resolution:    128 128 128\nFormat: SHORT\nByteOrder: BigEndian\nUnknownKey: 7\n",
        )
        .expect("valid");
        assert_eq!((d.ty, d.endian), (Some(VoxelType::I16), Some(Endian::Big)));
    }

    #[test]
    fn reads_invesalius_plists() {
        let xml = br#"<?xml version="1.0" encoding="UTF-8"?>
<plist version="1.0"><dict>
  <key>matrix</key><dict><key>dtype</key><string>int16</string>
    <key>shape</key><array><integer>108</integer><integer>256</integer><integer>200</integer></array></dict>
  <key>spacing</key><array><real>0.95</real><real>0.9</real><real>1.5</real></array>
</dict></plist>"#;
        let d = parse_invesalius_plist(xml).expect("valid plist");
        assert_eq!(d.dims, Some([200, 256, 108]), "shape is z, y, x");
        assert_eq!(d.spacing, Some([0.95, 0.9, 1.5]));
        assert_eq!(d.ty, Some(VoxelType::I16));
        assert!(parse_invesalius_plist(b"<plist><dict></dict></plist>").is_err());
        assert!(parse_invesalius_plist(b"not xml").is_err());
    }

    #[test]
    fn rejects_bad_sidecar_values() {
        for bad in [
            "ObjectFileName:",
            "ObjectFileName:   ",
            "Resolution: 1 2",
            "Resolution: a b c",
            "Format: RGB",
            "garbage line",
            "ByteOrder: middle",
        ] {
            assert!(parse_dat(bad).is_err(), "{bad:?} should be rejected");
        }
    }
}
