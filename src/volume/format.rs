//! Format detection and the one entry point for loading and saving volumes.

use super::pvm::{self, DdsVersion, PvmSamples, PvmVersion, PvmVoxels};
use super::raw::{self, RawOverrides};
use super::{Reading, Volume, fmt_dims};
use super::{
    VolumeError, VoxelData, analyze, dicom, fmt_bytes, memory_budget, mgh, nifti, nrrd, zarr,
};
use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The file format a volume came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Nifti {
        version: u8,
        gzip: bool,
        pair: bool,
    },
    Pvm {
        version: PvmVersion,
        dds: Option<DdsVersion>,
    },
    Raw {
        /// ".dat" or ".plist" when a sidecar described the layout.
        sidecar: Option<&'static str>,
    },
    Nrrd {
        /// `.nhdr` with `data file:` rather than attached voxels.
        detached: bool,
        encoding: nrrd::Encoding,
    },
    /// Analyze 7.5 `.hdr`/`.img` (no NIfTI magic).
    Analyze {
        gzip: bool,
    },
    /// FreeSurfer MGH (`.mgh`), or MGZ when gzip-compressed.
    Mgh {
        gzip: bool,
    },
    Dicom {
        /// Files whose images form the volume.
        files: usize,
        /// Slices (single-frame files or frames of multi-frame files).
        slices: usize,
    },
    /// An OME-Zarr store (a folder): one level of its multiscale pyramid.
    OmeZarr {
        ngff: zarr::NgffVersion,
        /// Zarr format, 2 or 3.
        zarr_format: u8,
        /// The level read (0 = full resolution) and how many the store has.
        level: usize,
        levels: usize,
    },
    Demo,
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Format::Nifti {
                version,
                gzip,
                pair,
            } => {
                write!(f, "NIfTI-{version}")?;
                if *pair {
                    f.write_str(" (.hdr/.img pair)")?;
                }
                if *gzip {
                    f.write_str(", gzip")?;
                }
                Ok(())
            }
            Format::Pvm { version, dds } => {
                let v = match version {
                    PvmVersion::Pvm1 => "PVM",
                    PvmVersion::Pvm2 => "PVM2",
                    PvmVersion::Pvm3 => "PVM3",
                };
                match dds {
                    Some(DdsVersion::V3d) => write!(f, "{v}, DDS v3d compressed"),
                    Some(DdsVersion::V3e) => write!(f, "{v}, DDS v3e compressed"),
                    None => f.write_str(v),
                }
            }
            Format::Raw {
                sidecar: Some(kind),
            } => write!(f, "raw with {kind} sidecar"),
            Format::Raw { sidecar: None } => f.write_str("raw"),
            Format::Nrrd { detached, encoding } => {
                let enc = match encoding {
                    nrrd::Encoding::Raw => "raw",
                    nrrd::Encoding::Gzip => "gzip",
                    nrrd::Encoding::Ascii => "ascii",
                    nrrd::Encoding::Hex => "hex",
                };
                let how = if *detached {
                    "detached header"
                } else {
                    "attached"
                };
                write!(f, "NRRD ({how}, {enc})")
            }
            Format::Analyze { gzip } => {
                f.write_str("Analyze 7.5 (.hdr/.img pair)")?;
                if *gzip {
                    f.write_str(", gzip")?;
                }
                Ok(())
            }
            Format::Mgh { gzip: false } => f.write_str("MGH (FreeSurfer)"),
            Format::Mgh { gzip: true } => f.write_str("MGZ (FreeSurfer MGH, gzip)"),
            Format::Dicom { files, slices } => {
                if *files == 1 && *slices > 1 {
                    write!(f, "DICOM, one multi-frame file of {slices} frames")
                } else if *files == 1 {
                    f.write_str("DICOM, one image")
                } else {
                    write!(f, "DICOM series of {files} files")
                }
            }
            Format::OmeZarr {
                ngff,
                zarr_format,
                level,
                levels,
            } => write!(
                f,
                "OME-Zarr {} (Zarr v{zarr_format}), level {level} of {levels}",
                ngff.name()
            ),
            Format::Demo => f.write_str("built-in demo volume"),
        }
    }
}

/// What the caller knows beyond the file: which 4-D frame, raw layout flags, a memory cap.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// 4-D NIfTI, NRRD or MGH: which 3-D frame (0-based) to load.
    pub frame: usize,
    /// Raw layout given on the command line (overrides a `.dat` sidecar field by field).
    pub raw: RawOverrides,
    /// Refuse headers claiming more voxel bytes than this (default: available memory).
    pub max_bytes: Option<u64>,
    /// DICOM folder: which series, by its number in `volao info`'s list (from 0) or its
    /// SeriesInstanceUID; `None` = the one with the most slices.
    pub series: Option<String>,
    /// OME-Zarr: which multiscale level (0 = full resolution, as `volao info` lists them).
    pub level: usize,
}

/// A loaded volume with its format and any non-fatal problems found on the way.
#[derive(Debug, Clone)]
pub struct Loaded {
    pub volume: Volume,
    pub format: Format,
    /// The file the voxels were read from (differs from the argument for sidecars and pairs).
    pub data_path: PathBuf,
    /// Things the user should know but that did not stop loading (one line each).
    pub warnings: Vec<String>,
}

/// Loads a volume, choosing the reader from the raw flags, the extension, then magic bytes.
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Loaded, VolumeError> {
    load_with_progress(path, opts, &mut |_, _| {})
}

enum Kind {
    Nifti,
    Pvm,
    Raw,
    Nrrd,
    Mgh,
    Dicom,
    OmeZarr,
}

fn detect(path: &Path, opts: &LoadOptions) -> Result<Kind, VolumeError> {
    if !opts.raw.is_empty() {
        return Ok(Kind::Raw);
    }
    if zarr::is_zarr_store(path) {
        return Ok(Kind::OmeZarr);
    }
    if path.is_dir() {
        return Ok(Kind::Dicom);
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    // The magic bytes first: a DICOM preamble may start with anything (even 348).
    let mut head = [0u8; 132];
    let mut n = 0;
    let mut f = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    while n < head.len() {
        match f.read(&mut head[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(VolumeError::io(path, e)),
        }
    }
    let head = &head[..n];
    if dicom::has_dicm_magic(head) {
        return Ok(Kind::Dicom);
    }
    if head.starts_with(b"NRRD000") {
        return Ok(Kind::Nrrd);
    }
    if nifti::is_nifti_path(path) {
        return Ok(Kind::Nifti);
    }
    match ext.as_str() {
        "pvm" => return Ok(Kind::Pvm),
        "raw" | "dat" => return Ok(Kind::Raw),
        "nrrd" | "nhdr" => return Ok(Kind::Nrrd),
        "mgh" | "mgz" => return Ok(Kind::Mgh),
        "gz" if path
            .to_string_lossy()
            .to_ascii_lowercase()
            .ends_with(".mgh.gz") =>
        {
            return Ok(Kind::Mgh);
        }
        "dcm" | "dicom" | "ima" => return Ok(Kind::Dicom),
        _ => {}
    }
    let le = head
        .get(..4)
        .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let be = head
        .get(..4)
        .map(|b| i32::from_be_bytes([b[0], b[1], b[2], b[3]]));
    if head.starts_with(b"PVM") || head.starts_with(b"DDS v3") {
        Ok(Kind::Pvm)
    } else if head.starts_with(&[0x1f, 0x8b])
        || [le, be].iter().any(|v| matches!(v, Some(348 | 540)))
    {
        Ok(Kind::Nifti)
    } else if raw::find_sidecar(path).is_some() {
        Ok(Kind::Raw)
    } else {
        Err(VolumeError::UnknownFormat {
            path: path.to_owned(),
        })
    }
}

/// The first 348 bytes of a NIfTI-1/Analyze header file (decompressed), if it has them
/// and they are Analyze 7.5 (no NIfTI magic).
fn analyze_header(header: &Path) -> Option<[u8; 348]> {
    let (mut r, _, _) = nifti::open_maybe_gz(header).ok()?;
    let mut buf = [0u8; 348];
    r.read_exact(&mut buf).ok()?;
    analyze::is_analyze(&buf).then_some(buf)
}

/// [`load`] with a progress callback `(bytes done, bytes total)` for the voxel read.
pub fn load_with_progress(
    path: &Path,
    opts: &LoadOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Loaded, VolumeError> {
    if !path.exists() {
        return Err(VolumeError::invalid(path, "no such file or folder"));
    }
    let max_bytes = opts.max_bytes.unwrap_or_else(memory_budget);
    let kind = detect(path, opts)?;
    if opts.series.is_some() && !matches!(kind, Kind::Dicom) {
        return Err(VolumeError::invalid(
            path,
            "--series applies to DICOM folders and files only",
        ));
    }
    if opts.level != 0 && !matches!(kind, Kind::OmeZarr) {
        return Err(VolumeError::invalid(
            path,
            "--level applies to OME-Zarr stores only",
        ));
    }
    let mut loaded = load_kind(kind, path, opts, max_bytes, progress)?;
    // Every reader's spacing goes through the same range check (a no-op for readers
    // that already made it with their own field names).
    let field = match loaded.format {
        Format::Pvm { .. } => "PVM voxel spacing",
        Format::Raw {
            sidecar: Some(".dat"),
        } => ".dat SliceThickness",
        Format::Raw { sidecar: Some(_) } => ".plist spacing",
        Format::Raw { sidecar: None } => "--spacing",
        _ => "spacing",
    };
    let fields = ["x", "y", "z"].map(|a| format!("{field} ({a})"));
    let fields = [fields[0].as_str(), fields[1].as_str(), fields[2].as_str()];
    let v = &mut loaded.volume;
    super::fix_spacing(
        &mut v.spacing,
        &mut v.orientation,
        &fields,
        &mut loaded.warnings,
    );
    super::fit_f64_to_f32(&mut loaded.volume, &mut loaded.warnings);
    Ok(loaded)
}

fn load_kind(
    kind: Kind,
    path: &Path,
    opts: &LoadOptions,
    max_bytes: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Loaded, VolumeError> {
    let mut warnings = Vec::new();
    let reading = Reading {
        max_bytes,
        warnings: &mut warnings,
        progress,
    };
    match kind {
        Kind::OmeZarr => {
            let z = zarr::load(path, opts.level, opts.frame, reading)?;
            Ok(Loaded {
                volume: z.volume,
                format: Format::OmeZarr {
                    ngff: z.ngff,
                    zarr_format: z.zarr_format,
                    level: z.level,
                    levels: z.levels,
                },
                data_path: path.to_owned(),
                warnings,
            })
        }
        Kind::Dicom => {
            if opts.frame != 0 {
                return Err(VolumeError::invalid(
                    path,
                    "DICOM: --frame does not apply (frames of a multi-frame file are slices); use --series to choose a series",
                ));
            }
            let (volume, info, data_path) = dicom::load(path, opts.series.as_deref(), reading)?;
            Ok(Loaded {
                volume,
                format: Format::Dicom {
                    files: info.files,
                    slices: info.frames,
                },
                data_path,
                warnings,
            })
        }
        Kind::Nrrd => {
            let h = nrrd::read_header_file(path)?;
            let detached = !h.data_files.is_empty();
            let (volume, data_path) = nrrd::load(path, opts.frame, reading)?;
            Ok(Loaded {
                volume,
                format: Format::Nrrd {
                    detached,
                    encoding: h.encoding,
                },
                data_path,
                warnings,
            })
        }
        Kind::Mgh => {
            let (volume, _) = mgh::load(path, opts.frame, reading)?;
            Ok(Loaded {
                volume,
                format: Format::Mgh {
                    gzip: is_gzip(path),
                },
                data_path: path.to_owned(),
                warnings,
            })
        }
        Kind::Nifti if analyze_header(&nifti::resolve_paths(path).header).is_some() => {
            let paths = nifti::resolve_paths(path);
            let buf = analyze_header(&paths.header).unwrap_or([0; 348]);
            if opts.frame != 0 {
                return Err(VolumeError::invalid(
                    path,
                    "Analyze 7.5: --frame is not supported; frame 0 is read",
                ));
            }
            let volume = analyze::load(&paths.header, &paths.image, &buf, reading)?;
            Ok(Loaded {
                volume,
                format: Format::Analyze {
                    gzip: is_gzip(&paths.image),
                },
                data_path: paths.image,
                warnings,
            })
        }
        Kind::Nifti => {
            let (volume, header) = nifti::load(path, opts.frame, reading)?;
            let paths = nifti::resolve_paths(path);
            let gzip = is_gzip(&paths.image);
            let pair = paths.image != paths.header;
            Ok(Loaded {
                volume,
                format: Format::Nifti {
                    version: header.version,
                    gzip,
                    pair,
                },
                data_path: paths.image,
                warnings,
            })
        }
        Kind::Pvm => {
            if opts.frame != 0 {
                return Err(VolumeError::invalid(
                    path,
                    "PVM files hold a single frame; --frame does not apply",
                ));
            }
            let (volume, format) = load_pvm(path, max_bytes, &mut warnings)?;
            Ok(Loaded {
                volume,
                format,
                data_path: path.to_owned(),
                warnings,
            })
        }
        Kind::Raw => {
            let (data_path, spec) = raw::resolve(path, &opts.raw)?;
            let sidecar = raw::find_sidecar(path).map(|s| s.kind());
            let volume =
                raw::load(&data_path, &spec, max_bytes, &mut warnings, progress).map_err(|e| {
                    if data_path == path {
                        e
                    } else {
                        super::with_context(e, path, "the voxel file it names")
                    }
                })?;
            Ok(Loaded {
                volume,
                format: Format::Raw { sidecar },
                data_path,
                warnings,
            })
        }
    }
}

fn is_gzip(path: &Path) -> bool {
    let mut magic = [0u8; 2];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok()
        && magic == [0x1f, 0x8b]
}

fn load_pvm(
    path: &Path,
    max_bytes: u64,
    warnings: &mut Vec<String>,
) -> Result<(Volume, Format), VolumeError> {
    let len = std::fs::metadata(path)
        .map_err(|e| VolumeError::io(path, e))?
        .len();
    if len > max_bytes {
        return Err(VolumeError::invalid(
            path,
            format!("file is {} — more than available memory", fmt_bytes(len)),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    pvm_to_volume(&bytes, max_bytes, path, warnings)
}

/// Decodes an in-memory PVM file (also used by fuzzing); `path` is for messages only.
pub fn pvm_to_volume(
    bytes: &[u8],
    max_bytes: u64,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<(Volume, Format), VolumeError> {
    let p =
        pvm::read_pvm(bytes, max_bytes).map_err(|e| VolumeError::invalid(path, e.to_string()))?;
    let spacing = p.spacing.unwrap_or_else(|| {
        warnings.push("plain PVM stores no voxel spacing; using 1 mm".into());
        [1.0; 3]
    });
    let data = match p.voxels {
        PvmVoxels::U8(v) => VoxelData::U8(v),
        PvmVoxels::U16(v) => VoxelData::U16(v),
    };
    let mut volume =
        Volume::new(p.dims, spacing, data).map_err(|m| VolumeError::invalid(path, m))?;
    volume.descriptions = p.descriptions;
    Ok((
        volume,
        Format::Pvm {
            version: p.version,
            dds: p.compression,
        },
    ))
}

/// Writes a volume in the format its extension names: `.nii`/`.nii.gz` (NIfTI),
/// `.nrrd`, `.pvm` (uncompressed PVM3), `.raw` (+ `.dat` sidecar) or `.zarr`/`.ome.zarr`
/// (an OME-Zarr 0.5 pyramid, a folder). Returns warnings.
pub fn save(volume: &Volume, path: &Path) -> Result<Vec<String>, VolumeError> {
    let lower = path.to_string_lossy().to_ascii_lowercase();
    let mut warnings = Vec::new();
    if lower.ends_with(".nii") || lower.ends_with(".nii.gz") {
        nifti::save(volume, path)?;
    } else if lower.ends_with(".pvm") {
        save_pvm(volume, path, &mut warnings)?;
    } else if lower.ends_with(".raw") {
        raw::save(volume, path, &mut warnings)?;
    } else if lower.ends_with(".nrrd") {
        nrrd::save(volume, path, &mut warnings)?;
    } else if lower.trim_end_matches(['/', '\\']).ends_with(".zarr") {
        zarr::save(volume, path, &mut warnings)?;
    } else {
        return Err(VolumeError::unsupported(
            path,
            "cannot tell the output format: use .nii, .nii.gz, .nrrd, .pvm, .raw or .ome.zarr",
        ));
    }
    Ok(warnings)
}

fn save_pvm(volume: &Volume, path: &Path, warnings: &mut Vec<String>) -> Result<(), VolumeError> {
    let voxels = match &volume.data {
        VoxelData::U8(v) => PvmSamples::U8(v),
        VoxelData::U16(v) => PvmSamples::U16(v),
        other => {
            return Err(VolumeError::unsupported(
                path,
                format!(
                    "PVM holds only unsigned 8- or 16-bit voxels; this {} volume is {} — write NIfTI (.nii.gz) instead",
                    fmt_dims(volume.dims),
                    other.voxel_type()
                ),
            ));
        }
    };
    if !volume.scaling.is_identity() {
        warnings.push(
            "PVM has no scaling field: stored values are written, slope/intercept are lost".into(),
        );
    }
    if volume.orientation.axis_codes() != "RAS" {
        warnings.push(format!(
            "PVM has no orientation field: the {} axis order is not recorded",
            volume.orientation.axis_codes()
        ));
    }
    let file = std::fs::File::create(path).map_err(|e| VolumeError::io(path, e))?;
    let w = std::io::BufWriter::new(file);
    pvm::write_pvm3(w, volume.dims, volume.spacing, voxels, &volume.descriptions)
        .map_err(|e| VolumeError::invalid(path, e.to_string()))
}
