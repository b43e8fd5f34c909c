//! The NIfTI writer: `.nii` or `.nii.gz`, NIfTI-1, or NIfTI-2 when a dimension exceeds
//! NIfTI-1's 32767, with the header encoded by hand (the `nifti` crate's writer resets
//! `scl_slope`).

use super::datatype_code;
use crate::volume::orient::Orientation;
use crate::volume::{Volume, VolumeError};
use std::io::Write;
use std::path::Path;

/// Writes `.nii` or `.nii.gz` (by extension): NIfTI-1, or NIfTI-2 when a dimension
/// exceeds NIfTI-1's 32767. Scaling, spacing, orientation and description are kept.
pub fn save(volume: &Volume, path: &Path) -> Result<(), VolumeError> {
    let lower = path.to_string_lossy().to_ascii_lowercase();
    if !(lower.ends_with(".nii") || lower.ends_with(".nii.gz")) {
        return Err(VolumeError::unsupported(
            path,
            "NIfTI output must end in .nii or .nii.gz",
        ));
    }
    let header = encode_header(volume);
    let file = std::fs::File::create(path).map_err(|e| VolumeError::io(path, e))?;
    let w = std::io::BufWriter::with_capacity(1 << 20, file);
    let result = if lower.ends_with(".gz") {
        let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::default());
        write_body(&mut gz, &header, volume).and_then(|_| gz.finish()?.flush())
    } else {
        let mut w = w;
        write_body(&mut w, &header, volume).and_then(|_| w.flush())
    };
    result.map_err(|e| VolumeError::io(path, e))
}

fn write_body(w: &mut impl Write, header: &[u8], volume: &Volume) -> std::io::Result<()> {
    w.write_all(header)?;
    w.write_all(&[0u8; 4])?; // no extensions
    // Little-endian on disk.
    if cfg!(target_endian = "little") {
        w.write_all(volume.data.as_bytes())
    } else {
        let mut swapped = volume.data.clone();
        swapped.swap_bytes();
        w.write_all(swapped.as_bytes())
    }
}

/// Little-endian header bytes (348 for NIfTI-1, 540 for NIfTI-2).
pub fn encode_header(volume: &Volume) -> Vec<u8> {
    let v2 = volume.dims.iter().any(|&d| d > i16::MAX as usize);
    let ty = volume.data.voxel_type();
    // Write an sform unless the orientation is exactly what a reader assumes without one.
    let (sform_code, srow): (i32, _) =
        if volume.orientation == Orientation::from_spacing(volume.spacing) {
            (0, [[0.0; 4]; 3])
        } else {
            (2, volume.orientation.rows())
        };
    let mut descrip = volume
        .descriptions
        .iter()
        .find(|(k, _)| k == "description")
        .or(volume.descriptions.first())
        .map(|(_, t)| t.as_bytes().to_vec())
        .unwrap_or_default();
    descrip.truncate(79);
    // descrip (80 bytes, NUL-padded) and aux_file (24, empty): the same in both versions.
    let mut descrip_aux = [0u8; 80 + 24];
    descrip_aux[..descrip.len()].copy_from_slice(&descrip);
    let pixdim = [
        1.0,
        volume.spacing[0] as f64,
        volume.spacing[1] as f64,
        volume.spacing[2] as f64,
        0.0,
        0.0,
        0.0,
        0.0,
    ];
    let dim = [
        3i64,
        volume.dims[0] as i64,
        volume.dims[1] as i64,
        volume.dims[2] as i64,
        1,
        1,
        1,
        1,
    ];
    let s = volume.scaling;
    let mut b = Vec::with_capacity(540);
    if v2 {
        b.extend(540i32.to_le_bytes());
        b.extend(b"n+2\0\r\n\x1a\n");
        b.extend(datatype_code(ty).to_le_bytes());
        b.extend((ty.size() as i16 * 8).to_le_bytes());
        dim.iter().for_each(|d| b.extend(d.to_le_bytes()));
        b.extend([0u8; 24]); // intent_p1..3
        pixdim.iter().for_each(|p| b.extend(p.to_le_bytes()));
        b.extend(544i64.to_le_bytes());
        b.extend(s.slope.to_le_bytes());
        b.extend(s.inter.to_le_bytes());
        b.extend([0u8; 8 * 4]); // cal_max, cal_min, slice_duration, toffset
        b.extend([0u8; 16]); // slice_start, slice_end
        b.extend(descrip_aux);
        b.extend(0i32.to_le_bytes()); // qform_code
        b.extend(sform_code.to_le_bytes());
        b.extend([0u8; 48]); // quatern_b..d, qoffset_x..z
        srow.iter()
            .flatten()
            .for_each(|v| b.extend(v.to_le_bytes()));
        b.extend(0i32.to_le_bytes()); // slice_code
        b.extend(2i32.to_le_bytes()); // xyzt_units: mm
        b.extend(0i32.to_le_bytes()); // intent_code
        b.extend([0u8; 16 + 1 + 15]); // intent_name, dim_info, unused
        debug_assert_eq!(b.len(), 540);
    } else {
        b.extend(348i32.to_le_bytes());
        b.extend([0u8; 10 + 18 + 4 + 2 + 1 + 1]); // data_type .. dim_info
        dim.iter().for_each(|d| b.extend((*d as i16).to_le_bytes()));
        b.extend([0u8; 12]); // intent_p1..3
        b.extend(0i16.to_le_bytes()); // intent_code
        b.extend(datatype_code(ty).to_le_bytes());
        b.extend((ty.size() as i16 * 8).to_le_bytes());
        b.extend(0i16.to_le_bytes()); // slice_start
        pixdim
            .iter()
            .for_each(|p| b.extend((*p as f32).to_le_bytes()));
        b.extend(352f32.to_le_bytes());
        b.extend((s.slope as f32).to_le_bytes());
        b.extend((s.inter as f32).to_le_bytes());
        b.extend(0i16.to_le_bytes()); // slice_end
        b.push(0); // slice_code
        b.push(2); // xyzt_units: mm
        b.extend([0u8; 16]); // cal_max, cal_min, slice_duration, toffset
        b.extend([0u8; 8]); // glmax, glmin
        b.extend(descrip_aux);
        b.extend(0i16.to_le_bytes()); // qform_code
        b.extend((sform_code as i16).to_le_bytes());
        b.extend([0u8; 24]); // quatern_b..d, qoffset_x..z
        srow.iter()
            .flatten()
            .for_each(|v| b.extend((*v as f32).to_le_bytes()));
        b.extend([0u8; 16]); // intent_name
        b.extend(b"n+1\0");
        debug_assert_eq!(b.len(), 348);
    }
    b
}
