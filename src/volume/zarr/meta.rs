//! OME-Zarr metadata as volao reads it: the first multiscale image of a group, its axes
//! (which are spatial, their units in mm), each level's scale and translation, and the
//! axes' anatomical orientation (the RFC-4 proposal's per-axis `orientation`).
//!
//! Structure and validation come from `ome_zarr_metadata` (NGFF 0.4 and 0.5). Two things
//! it does not keep are read from the JSON beside it: RFC-4's `orientation` (its axis
//! type refuses unknown fields, so the key is taken out before it parses) and the
//! transforms' numbers as f64 (it keeps f32, which would move an origin of a few hundred
//! mm by micrometres).

use ome_zarr_metadata::v0_5::{AxisType, MultiscaleImage};
use ome_zarr_metadata::{Validate, v0_4, v0_5};
use serde_json::Value;

/// The NGFF version of a store's metadata.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NgffVersion {
    /// 0.4: Zarr v2, fields at the top of `.zattrs`.
    V0_4,
    /// 0.5: Zarr v3, fields under `ome` in `zarr.json`'s attributes.
    V0_5,
}

impl NgffVersion {
    pub fn name(self) -> &'static str {
        match self {
            NgffVersion::V0_4 => "0.4",
            NgffVersion::V0_5 => "0.5",
        }
    }
}

/// What an axis holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AxisKind {
    Space,
    Time,
    Channel,
    /// A custom or missing type on a non-spatial axis.
    Other(String),
}

#[derive(Debug, Clone)]
pub struct AxisMeta {
    pub name: String,
    pub kind: AxisKind,
    /// Millimetres per unit of a spatial axis; `None` when the axis names no unit.
    pub mm_per_unit: Option<f64>,
    /// The unit as written, for messages.
    pub unit: Option<String>,
}

/// One resolution level: its array's path and, per axis, coordinate = index · scale +
/// translation (the multiscale's own transforms composed in).
#[derive(Debug, Clone)]
pub struct LevelMeta {
    pub path: String,
    pub scale: Vec<f64>,
    pub translation: Vec<f64>,
}

/// A multiscale image as volao reads it.
#[derive(Debug, Clone)]
pub struct Multiscale {
    pub version: NgffVersion,
    pub axes: Vec<AxisMeta>,
    pub levels: Vec<LevelMeta>,
    /// For volao's voxel axes x, y, z (x fastest): the array axis each one is (the last,
    /// middle and first of the three spatial axes).
    pub spatial: [usize; 3],
    /// For volao's voxel axes x, y, z: the world axis (0 = L/R, 1 = P/A, 2 = I/S) and
    /// whether coordinates grow towards R, A resp. S. `None` when the metadata has no
    /// usable RFC-4 orientation.
    pub orientation: Option<[(usize, bool); 3]>,
    /// Things the user should know (more than one multiscale image, odd orientation).
    pub warnings: Vec<String>,
}

/// The RFC-4 value for world axis `w` (0 = L/R, 1 = P/A, 2 = I/S) in direction `positive`.
pub fn orientation_name(w: usize, positive: bool) -> &'static str {
    match (w, positive) {
        (0, true) => "left-to-right",
        (0, false) => "right-to-left",
        (1, true) => "posterior-to-anterior",
        (1, false) => "anterior-to-posterior",
        (_, true) => "inferior-to-superior",
        (_, false) => "superior-to-inferior",
    }
}

/// The world axis and direction of an RFC-4 anatomical value; `None` for values with no
/// place in RAS (dorsal-to-ventral, rostral-to-caudal, …: they depend on the species).
fn parse_orientation(value: &str) -> Option<(usize, bool)> {
    (0..3)
        .flat_map(|w| [(w, true), (w, false)])
        .find(|&(w, p)| orientation_name(w, p) == value)
}

/// Millimetres per unit for the UDUNITS-2 length units NGFF lists (and their usual
/// abbreviations); `None` for anything else.
pub fn mm_per_unit(unit: &str) -> Option<f64> {
    Some(match unit {
        "angstrom" | "Å" => 1e-7,
        "attometer" => 1e-15,
        "femtometer" => 1e-12,
        "picometer" | "pm" => 1e-9,
        "nanometer" | "nm" => 1e-6,
        "micrometer" | "micron" | "um" | "µm" | "μm" => 1e-3,
        "millimeter" | "mm" => 1.0,
        "centimeter" | "cm" => 10.0,
        "decimeter" | "dm" => 100.0,
        "meter" | "m" => 1e3,
        "hectometer" => 1e5,
        "kilometer" | "km" => 1e6,
        "inch" | "in" => 25.4,
        "foot" | "ft" => 304.8,
        "yard" => 914.4,
        "mile" => 1_609_344.0,
        _ => return None,
    })
}

/// Reads the multiscale image in a group's attributes. `Err` is a message without the
/// path (the caller adds it).
pub fn parse(attributes: &serde_json::Map<String, Value>) -> Result<Multiscale, String> {
    let attrs = Value::Object(attributes.clone());
    let (version, fields) = match attrs.get("ome") {
        Some(ome) => (NgffVersion::V0_5, ome),
        None => (NgffVersion::V0_4, &attrs),
    };
    let Some(raw_multiscales) = fields.get("multiscales").and_then(Value::as_array) else {
        return Err(
            "a Zarr group without OME-Zarr \"multiscales\" metadata (volao reads OME-Zarr images; plates, wells and label-only groups are not read)"
                .into(),
        );
    };
    let Some(raw) = raw_multiscales.first() else {
        return Err("OME-Zarr \"multiscales\" is empty".into());
    };
    let orientations = axis_orientations(raw);
    let cleaned = strip_orientations(&attrs);
    // Each version's own type (not `AnyOmeFields`, whose untagged enum hides serde's
    // message behind "did not match any variant").
    let bad = |e: String| format!("bad OME-Zarr {} metadata: {}", version.name(), one_line(&e));
    let invalid = |e: String| {
        format!(
            "invalid OME-Zarr {} metadata: {}",
            version.name(),
            one_line(&e)
        )
    };
    let multiscales: Vec<MultiscaleImage> = match version {
        NgffVersion::V0_5 => {
            let ome = cleaned.get("ome").cloned().unwrap_or_default();
            let f: v0_5::OmeFields = serde_json::from_value(ome).map_err(|e| bad(e.to_string()))?;
            f.validate().map_err(|e| invalid(e.to_string()))?;
            f.multiscales.unwrap_or_default()
        }
        NgffVersion::V0_4 => {
            let f: v0_4::OmeNgffGroupAttributes =
                serde_json::from_value(cleaned).map_err(|e| bad(e.to_string()))?;
            f.validate().map_err(|e| invalid(e.to_string()))?;
            f.multiscales
                .unwrap_or_default()
                .into_iter()
                .map(MultiscaleImage::from)
                .collect()
        }
    };
    let Some(image) = multiscales.first() else {
        return Err("OME-Zarr \"multiscales\" is empty".into());
    };
    let mut warnings = Vec::new();
    if multiscales.len() > 1 {
        warnings.push(format!(
            "the store holds {} multiscale images; reading the first",
            multiscales.len()
        ));
    }

    let axes: Vec<AxisMeta> = image.axes.iter().map(axis_meta).collect();
    let n = axes.len();
    let space: Vec<usize> = (0..n)
        .filter(|&i| axes[i].kind == AxisKind::Space)
        .collect();
    if space.len() != 3 || space != [n - 3, n - 2, n - 1] {
        let names: Vec<&str> = axes.iter().map(|a| a.name.as_str()).collect();
        return Err(format!(
            "has {} spatial axes ({}); volao reads 3-D images, whose last three axes are spatial (z, y, x)",
            space.len(),
            names.join(", ")
        ));
    }
    let spatial = [n - 1, n - 2, n - 3];
    for &a in &spatial {
        if let Some(u) = &axes[a].unit
            && axes[a].mm_per_unit.is_none()
        {
            return Err(format!(
                "axis {} has unit {u:?}, which is not a length volao knows",
                axes[a].name
            ));
        }
    }

    let global = raw
        .get("coordinateTransformations")
        .map(|t| transforms(t, n))
        .transpose()?;
    let raw_datasets = raw.get("datasets").and_then(Value::as_array);
    let mut levels = Vec::with_capacity(image.datasets.len());
    for (k, ds) in image.datasets.iter().enumerate() {
        let t = raw_datasets
            .and_then(|d| d.get(k))
            .and_then(|d| d.get("coordinateTransformations"))
            .ok_or_else(|| format!("dataset {k} has no coordinateTransformations"))?;
        let (mut scale, mut translation) = transforms(t, n)?;
        if let Some((gs, gt)) = &global {
            for (((s, t), g), o) in scale.iter_mut().zip(&mut translation).zip(gs).zip(gt) {
                *s *= g;
                *t = *t * g + o;
            }
        }
        levels.push(LevelMeta {
            path: ds.path.clone(),
            scale,
            translation,
        });
    }

    let orientation = read_orientation(&orientations, &axes, spatial, &mut warnings)?;
    Ok(Multiscale {
        version,
        axes,
        levels,
        spatial,
        orientation,
        warnings,
    })
}

fn axis_meta(a: &ome_zarr_metadata::v0_5::Axis) -> AxisMeta {
    let unit = a
        .unit
        .as_ref()
        .and_then(|u| serde_json::to_value(u).ok())
        .and_then(|v| v.as_str().map(str::to_owned));
    let kind = match &a.r#type {
        Some(AxisType::Space) => AxisKind::Space,
        Some(AxisType::Time) => AxisKind::Time,
        Some(AxisType::Channel) => AxisKind::Channel,
        // NGFF 0.4 allows axes without a type: x, y and z are still spatial.
        None if matches!(a.name.as_str(), "x" | "y" | "z") => AxisKind::Space,
        Some(AxisType::Custom(t)) => AxisKind::Other(t.clone()),
        None | Some(_) => AxisKind::Other("untyped".into()),
    };
    AxisMeta {
        name: a.name.clone(),
        mm_per_unit: unit.as_deref().and_then(mm_per_unit),
        kind,
        unit,
    }
}

/// A list of transforms (a scale, then optionally a translation) as f64 per axis.
fn transforms(list: &Value, n: usize) -> Result<(Vec<f64>, Vec<f64>), String> {
    let mut scale = vec![1.0; n];
    let mut translation = vec![0.0; n];
    for t in list.as_array().into_iter().flatten() {
        let kind = t.get("type").and_then(Value::as_str).unwrap_or("");
        let (key, into) = match kind {
            "scale" => ("scale", &mut scale),
            "translation" => ("translation", &mut translation),
            "identity" => continue,
            other => return Err(format!("coordinate transform {other:?} is not supported")),
        };
        let Some(values) = t.get(key).and_then(Value::as_array) else {
            return Err(format!(
                "{kind} transforms stored in a separate array (\"path\") are not supported"
            ));
        };
        let values: Option<Vec<f64>> = values.iter().map(Value::as_f64).collect();
        match values {
            Some(v) if v.len() == n && v.iter().all(|x| x.is_finite()) => *into = v,
            _ => {
                return Err(format!(
                    "{kind} transform needs {n} finite numbers, one per axis"
                ));
            }
        }
    }
    Ok((scale, translation))
}

/// The raw `orientation` object of each axis of one multiscale image.
fn axis_orientations(multiscale: &Value) -> Vec<Option<Value>> {
    multiscale
        .get("axes")
        .and_then(Value::as_array)
        .map(|axes| axes.iter().map(|a| a.get("orientation").cloned()).collect())
        .unwrap_or_default()
}

/// The attributes with every axis's `orientation` taken out (so the strict 0.4/0.5
/// types parse them).
fn strip_orientations(attrs: &Value) -> Value {
    let mut out = attrs.clone();
    let namespaced = out.get("ome").is_some();
    let fields = if namespaced {
        out.get_mut("ome")
    } else {
        Some(&mut out)
    };
    if let Some(list) = fields
        .and_then(|f| f.get_mut("multiscales"))
        .and_then(Value::as_array_mut)
    {
        for m in list {
            if let Some(axes) = m.get_mut("axes").and_then(Value::as_array_mut) {
                for a in axes {
                    if let Some(obj) = a.as_object_mut() {
                        obj.remove("orientation");
                    }
                }
            }
        }
    }
    out
}

/// The spatial axes' RFC-4 orientation: all three anatomical and on distinct world
/// axes, else `None` with a warning (or an error for a contradiction).
fn read_orientation(
    raw: &[Option<Value>],
    axes: &[AxisMeta],
    spatial: [usize; 3],
    warnings: &mut Vec<String>,
) -> Result<Option<[(usize, bool); 3]>, String> {
    let given: Vec<usize> = spatial
        .iter()
        .copied()
        .filter(|&a| raw.get(a).is_some_and(Option::is_some))
        .collect();
    if given.is_empty() {
        return Ok(None);
    }
    if given.len() < 3 {
        warnings
            .push("RFC-4 orientation is given on only some spatial axes; ignoring it".to_owned());
        return Ok(None);
    }
    let mut out = [(0, true); 3];
    let mut used = [false; 3];
    for (slot, &a) in spatial.iter().enumerate() {
        let o = raw[a].as_ref().unwrap_or(&Value::Null);
        let ty = o.get("type").and_then(Value::as_str);
        let value = o.get("value").and_then(Value::as_str);
        let name = &axes[a].name;
        let (Some("anatomical"), Some(value)) = (ty, value) else {
            warnings.push(format!(
                "axis {name}: orientation {} is not an RFC-4 anatomical orientation; ignoring the orientations",
                one_line(&o.to_string())
            ));
            return Ok(None);
        };
        let Some((w, pos)) = parse_orientation(value) else {
            warnings.push(format!(
                "axis {name}: orientation {value:?} has no left/right, anterior/posterior or inferior/superior meaning; ignoring the orientations"
            ));
            return Ok(None);
        };
        if used[w] {
            return Err(format!(
                "RFC-4 orientation: two axes run along the same anatomical axis ({value:?} on axis {name})"
            ));
        }
        used[w] = true;
        out[slot] = (w, pos);
    }
    Ok(Some(out))
}

/// An error message from a parser on one line.
pub fn one_line(s: &str) -> String {
    let s = s.split_whitespace().collect::<Vec<_>>().join(" ");
    if s.chars().count() > 300 {
        let cut: String = s.chars().take(300).collect();
        format!("{cut}…")
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn attrs(v: Value) -> serde_json::Map<String, Value> {
        v.as_object().cloned().unwrap_or_default()
    }

    fn v05(axes: Value, transforms: Value) -> serde_json::Map<String, Value> {
        attrs(json!({"ome": {"version": "0.5", "multiscales": [{
            "axes": axes,
            "datasets": [{"path": "s0", "coordinateTransformations": transforms}]
        }]}}))
    }

    fn zyx() -> Value {
        json!([
            {"name": "z", "type": "space", "unit": "micrometer"},
            {"name": "y", "type": "space", "unit": "micrometer"},
            {"name": "x", "type": "space", "unit": "micrometer"}
        ])
    }

    #[test]
    fn units_scale_translation_and_axis_order() {
        let m = parse(&v05(
            zyx(),
            json!([{"type": "scale", "scale": [3.0, 2.0, 0.5]},
                   {"type": "translation", "translation": [10.0, 20.0, 30.25]}]),
        ))
        .expect("parses");
        assert_eq!(m.version, NgffVersion::V0_5);
        assert_eq!(m.spatial, [2, 1, 0]);
        assert_eq!(m.axes[0].mm_per_unit, Some(1e-3));
        assert_eq!(m.levels[0].scale, [3.0, 2.0, 0.5]);
        assert_eq!(m.levels[0].translation, [10.0, 20.0, 30.25]);
        assert_eq!(m.orientation, None);
    }

    #[test]
    fn rfc4_orientation_is_read_and_checked() {
        let mut axes = zyx();
        let values = [
            "superior-to-inferior",
            "posterior-to-anterior",
            "right-to-left",
        ];
        for (a, v) in axes.as_array_mut().into_iter().flatten().zip(values) {
            a["orientation"] = json!({"type": "anatomical", "value": v});
        }
        let scale = json!([{"type": "scale", "scale": [1.0, 1.0, 1.0]}]);
        let m = parse(&v05(axes.clone(), scale.clone())).expect("parses");
        // x (array axis 2) runs right-to-left, y posterior-to-anterior, z downwards.
        assert_eq!(m.orientation, Some([(0, false), (1, true), (2, false)]));
        axes[0]["orientation"]["value"] = json!("right-to-left");
        let e = parse(&v05(axes, scale)).expect_err("two L/R axes");
        assert!(e.contains("same anatomical axis"), "{e}");
    }

    #[test]
    fn v04_with_a_channel_axis_and_global_scale() {
        let m = parse(&attrs(json!({"multiscales": [{
            "version": "0.4",
            "axes": [{"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
                     {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
            "datasets": [{"path": "0", "coordinateTransformations":
                [{"type": "scale", "scale": [1.0, 2.0, 2.0, 2.0]},
                 {"type": "translation", "translation": [0.0, 1.0, 1.0, 1.0]}]}],
            "coordinateTransformations": [{"type": "scale", "scale": [1.0, 0.5, 0.5, 0.5]}]
        }]})))
        .expect("parses");
        assert_eq!(m.version, NgffVersion::V0_4);
        assert_eq!(m.spatial, [3, 2, 1]);
        assert_eq!(m.axes[0].kind, AxisKind::Channel);
        assert_eq!(m.levels[0].scale, [1.0, 1.0, 1.0, 1.0]);
        assert_eq!(m.levels[0].translation, [0.0, 0.5, 0.5, 0.5]);
    }

    #[test]
    fn bad_metadata_is_one_clear_message() {
        let e = parse(&attrs(json!({"foo": 1}))).expect_err("no multiscales");
        assert!(e.contains("without OME-Zarr \"multiscales\""), "{e}");
        let two_d = json!([{"name": "y", "type": "space"}, {"name": "x", "type": "space"}]);
        let e =
            parse(&v05(two_d, json!([{"type": "scale", "scale": [1.0, 1.0]}]))).expect_err("2-D");
        assert!(e.contains("2 spatial axes"), "{e}");
        let e = parse(&v05(zyx(), json!([{"type": "scale", "scale": [1.0]}])))
            .expect_err("short scale");
        assert!(!e.contains('\n'), "{e}");
    }
}
