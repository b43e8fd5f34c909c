//! Clip shapes for Contextual Ambient Occlusion (Titov et al. §3.2–3.6).
//!
//! A [`ClipShape`] is a closed triangle mesh with a pose in the volume's physical space
//! (millimetres, origin at the volume's centre, axes along the voxel axes — the space the
//! ray caster works in) and a mode: **carve** removes the inside, **probe** keeps only the
//! inside. Each shape gets its own orthographic clipping camera ([`camera::ClipCamera`])
//! attached to the mesh: its depth maps depend only on the mesh's geometry (shape and
//! scale), so translating or rotating a shape only changes a matrix.

pub mod camera;
pub mod cpu;
pub mod gpu;
pub mod gpu_data;
pub mod mesh;

use glam::{EulerRot, Mat4, Quat, Vec3};
use mesh::{MeshError, TriMesh};
use std::path::PathBuf;

/// Shapes clipping at once (CAO paper §3.6: each has its own clipping camera and maps).
pub const MAX_SHAPES: usize = 8;

/// The geometry of a clip shape before its pose.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    /// A half-space: everything on the side of local +z from the plane through the
    /// origin (built as a slab larger than any volume). Scale is ignored.
    Plane,
    /// Unit sphere; scale gives the radii.
    Sphere,
    /// Box `[-1, 1]³`; scale gives the half sizes.
    Box,
    /// Cylinder of radius 1 around local z, z in [-1, 1]; scale gives radii and half height.
    Cylinder,
    /// Torus around local y (ring in the xz plane), major radius 1, tube radius `tube`
    /// (relative to the major radius).
    Torus { tube: f32 },
    /// A closed OBJ or STL mesh (coordinates in mm), scaled by `scale`.
    Mesh { path: PathBuf },
}

/// Carve (subtract the inside, the paper's default) or probe (keep only the inside).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClipMode {
    #[default]
    Carve,
    Probe,
}

impl ClipMode {
    pub fn parse(s: &str) -> Result<ClipMode, String> {
        match s {
            "carve" => Ok(ClipMode::Carve),
            "probe" => Ok(ClipMode::Probe),
            other => Err(format!(
                "unknown clip mode {other:?} (available: carve, probe)"
            )),
        }
    }
}

/// A clip shape with its pose, as saved in scene files.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipShape {
    pub shape: Shape,
    /// Centre in mm from the volume's centre.
    pub translation: [f32; 3],
    /// Rotation in degrees about x, then y, then z (none when left out).
    #[serde(default)]
    pub rotation_deg: [f32; 3],
    /// Size in mm per local axis (see [`Shape`]).
    pub scale: [f32; 3],
    #[serde(default)]
    pub mode: ClipMode,
    /// Which segments of a segmentation it cuts (all when there is none).
    #[serde(default, skip_serializing_if = "Cuts::is_all")]
    pub cuts: Cuts,
}

/// Which segments a clip shape cuts: names (`*` matches any run of characters) or label
/// values, `unlabelled` for the voxels in no segment. A voxel in several overlapping
/// segments is cut only if the shape cuts all of them.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Cuts {
    #[default]
    All,
    Only(Vec<String>),
    Except(Vec<String>),
}

impl Cuts {
    pub fn is_all(&self) -> bool {
        *self == Cuts::All
    }

    /// `all`, `only=A,B,…` or `except=A,B,…` (the part of `--clip` after `;`).
    pub fn parse(s: &str) -> Result<Cuts, String> {
        let list = |l: &str| {
            l.split(',')
                .map(|n| n.trim().to_owned())
                .filter(|n| !n.is_empty())
                .collect()
        };
        match s.trim().split_once('=') {
            None if s.trim() == "all" => Ok(Cuts::All),
            Some(("only", l)) => Ok(Cuts::Only(list(l))),
            Some(("except", l)) => Ok(Cuts::Except(list(l))),
            _ => Err(format!(
                "segments {s:?}: expected all, only=NAME,… or except=NAME,…"
            )),
        }
    }
}

/// Why a clip shape cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ClipError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error("clip shape {index}: {message}")]
    Invalid { index: usize, message: String },
    #[error("{count} clip shapes given; at most {MAX_SHAPES} can clip at once")]
    TooMany { count: usize },
}

impl ClipShape {
    /// A shape of `shape` at `translation` with uniform size `size` mm.
    pub fn new(shape: Shape, translation: Vec3, size: f32) -> Self {
        ClipShape {
            shape,
            translation: translation.to_array(),
            rotation_deg: [0.0; 3],
            scale: [size; 3],
            mode: ClipMode::Carve,
            cuts: Cuts::All,
        }
    }

    pub fn rotation(&self) -> Quat {
        let [x, y, z] = self.rotation_deg.map(f32::to_radians);
        Quat::from_euler(EulerRot::XYZ, x, y, z)
    }

    /// Shape space (the scaled mesh, centred) → volume physical space: rotation, then
    /// translation. Moving a shape changes only this matrix.
    pub fn shape_to_volume(&self) -> Mat4 {
        Mat4::from_rotation_translation(self.rotation(), Vec3::from(self.translation))
    }

    /// Whether point `p` (volume-centred mm) lies inside the shape; `None` for a mesh
    /// (its inside is only known to the depth maps).
    pub fn contains(&self, p: Vec3) -> Option<bool> {
        self.contains_local(self.to_local(p))
    }

    /// Point `p` (volume-centred mm) in the shape's own frame: translated and rotated
    /// back, not scaled (an affine map, so callers testing many points can interpolate).
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        self.rotation().inverse() * (p - Vec3::from(self.translation))
    }

    /// [`Self::contains`] for a point already in the shape's frame ([`Self::to_local`]).
    pub fn contains_local(&self, local: Vec3) -> Option<bool> {
        let s = Vec3::from(self.scale).max(Vec3::splat(1e-6));
        let q = local / s;
        Some(match &self.shape {
            Shape::Plane => local.z >= 0.0,
            Shape::Sphere => q.length_squared() <= 1.0,
            Shape::Box => q.abs().max_element() <= 1.0,
            Shape::Cylinder => q.x * q.x + q.y * q.y <= 1.0 && q.z.abs() <= 1.0,
            Shape::Torus { tube } => {
                let ring = (q.x * q.x + q.z * q.z).sqrt() - 1.0;
                ring * ring + q.y * q.y <= tube * tube
            }
            Shape::Mesh { .. } => return None,
        })
    }

    /// Checks the pose; `index` names the shape in errors.
    pub fn check(&self, index: usize) -> Result<(), ClipError> {
        let invalid = |message: String| ClipError::Invalid { index, message };
        let numbers = self
            .translation
            .iter()
            .chain(&self.rotation_deg)
            .chain(&self.scale);
        if numbers.clone().any(|v| !v.is_finite()) {
            return Err(invalid(format!(
                "the pose has a non-finite number (translation {:?}, rotation {:?}, scale {:?})",
                self.translation, self.rotation_deg, self.scale
            )));
        }
        if self.shape != Shape::Plane && self.scale.iter().any(|&s| s <= 0.0) {
            return Err(invalid(format!(
                "the scale must be positive on every axis, got {:?}",
                self.scale
            )));
        }
        if let Shape::Torus { tube } = self.shape
            && !(tube > 0.0 && tube < 1.0)
        {
            return Err(invalid(format!(
                "a torus's tube radius must be between 0 and 1 (relative to the major radius), got {tube}"
            )));
        }
        Ok(())
    }

    /// Half the side of a plane's slab (mm): it covers the volume from wherever the plane
    /// sits, so it depends on the translation (and a plane's maps with it).
    pub fn plane_slab_size(&self, volume_radius: f32) -> f32 {
        4.0 * volume_radius.max(1.0) + Vec3::from(self.translation).length()
    }

    /// The mesh in shape space (scaled, not posed). `volume_radius` (mm) sizes the plane's
    /// slab so it covers the volume from any pose inside it.
    pub fn geometry(&self, volume_radius: f32) -> Result<TriMesh, ClipError> {
        let scale = Vec3::from(self.scale);
        let mesh = match &self.shape {
            Shape::Plane => {
                let l = self.plane_slab_size(volume_radius);
                mesh::cuboid(Vec3::new(-l, -l, 0.0), Vec3::new(l, l, l))
            }
            Shape::Sphere => mesh::sphere(48, 96).scaled(scale),
            Shape::Box => mesh::cuboid(Vec3::NEG_ONE, Vec3::ONE).scaled(scale),
            Shape::Cylinder => mesh::cylinder(96).scaled(scale),
            Shape::Torus { tube } => mesh::torus(*tube, 96, 48).scaled(scale),
            Shape::Mesh { path } => {
                let m = mesh::load(path)?;
                // Centre the file's mesh so the pose rotates it about its middle.
                let (lo, hi) = m.bounds();
                let c = (lo + hi) * 0.5;
                TriMesh {
                    vertices: m.vertices.iter().map(|v| (*v - c) * scale).collect(),
                    triangles: m.triangles,
                }
            }
        };
        Ok(mesh.validate(&self.describe())?)
    }

    /// The mesh posed in the volume's physical space (for drawing the shape).
    pub fn posed_geometry(&self, volume_radius: f32) -> Result<TriMesh, ClipError> {
        let m = self.geometry(volume_radius)?;
        let to_volume = self.shape_to_volume();
        Ok(TriMesh {
            vertices: m
                .vertices
                .iter()
                .map(|v| to_volume.transform_point3(*v))
                .collect(),
            triangles: m.triangles,
        })
    }

    /// e.g. "sphere at (10, 0, -5) mm".
    pub fn describe(&self) -> String {
        let name = match &self.shape {
            Shape::Plane => "plane".to_owned(),
            Shape::Sphere => "sphere".to_owned(),
            Shape::Box => "box".to_owned(),
            Shape::Cylinder => "cylinder".to_owned(),
            Shape::Torus { .. } => "torus".to_owned(),
            Shape::Mesh { path } => format!("mesh {}", path.display()),
        };
        let [x, y, z] = self.translation;
        format!("{name} at ({x}, {y}, {z}) mm")
    }

    /// Parses the CLI form (all lengths in mm, centres from the volume's centre):
    ///
    /// - `plane:PX,PY,PZ,NX,NY,NZ` — removes the side the normal points to
    /// - `sphere:CX,CY,CZ,R`
    /// - `box:CX,CY,CZ,SX,SY,SZ[,RX,RY,RZ]` — side lengths, rotation in degrees
    /// - `cylinder:CX,CY,CZ,R,H[,RX,RY,RZ]` — radius, height along local z
    /// - `torus:CX,CY,CZ,R,r[,RX,RY,RZ]` — major and tube radius
    /// - `mesh:PATH[,CX,CY,CZ[,S]]` — OBJ or STL, uniform scale S
    ///
    /// followed by `;only=NAME,…` or `;except=NAME,…` for the segments it cuts ([`Cuts`]).
    pub fn parse(spec: &str) -> Result<ClipShape, String> {
        // `SHAPE;only=…` or `SHAPE;except=…`: the segments it cuts.
        if let Some((shape, cuts)) = spec.split_once(';') {
            let cuts = Cuts::parse(cuts).map_err(|e| format!("clip shape {spec:?}: {e}"))?;
            return Ok(ClipShape {
                cuts,
                ..Self::parse(shape)?
            });
        }
        let (kind, rest) = spec.split_once(':').ok_or_else(|| {
            format!("clip shape {spec:?}: expected KIND:NUMBERS, e.g. sphere:0,0,0,20")
        })?;
        if kind == "mesh" {
            let mut parts = rest.split(',');
            let path = PathBuf::from(parts.next().unwrap_or_default());
            let nums = numbers(spec, parts)?;
            let centre = match nums.len() {
                0 => Vec3::ZERO,
                3 | 4 => Vec3::new(nums[0], nums[1], nums[2]),
                n => {
                    return Err(format!(
                        "clip shape {spec:?}: expected 0, 3 or 4 numbers after the path, got {n}"
                    ));
                }
            };
            let s = nums.get(3).copied().unwrap_or(1.0);
            return Ok(ClipShape::new(Shape::Mesh { path }, centre, s));
        }
        let n = numbers(spec, rest.split(','))?;
        let count = |allowed: &[usize]| -> Result<(), String> {
            if allowed.contains(&n.len()) {
                Ok(())
            } else {
                Err(format!(
                    "clip shape {spec:?}: {kind} takes {allowed:?} numbers, got {}",
                    n.len()
                ))
            }
        };
        let centre = || Vec3::new(n[0], n[1], n[2]);
        let rotation = |at: usize| -> [f32; 3] {
            if n.len() >= at + 3 {
                [n[at], n[at + 1], n[at + 2]]
            } else {
                [0.0; 3]
            }
        };
        let mut shape = match kind {
            "plane" => {
                count(&[6])?;
                let normal = Vec3::new(n[3], n[4], n[5]);
                if normal.length_squared() == 0.0 || !normal.is_finite() {
                    return Err(format!("clip shape {spec:?}: the plane's normal is zero"));
                }
                let q = Quat::from_rotation_arc(Vec3::Z, normal.normalize());
                let (x, y, z) = q.to_euler(EulerRot::XYZ);
                let mut s = ClipShape::new(Shape::Plane, centre(), 1.0);
                s.rotation_deg = [x, y, z].map(f32::to_degrees);
                s
            }
            "sphere" => {
                count(&[4])?;
                ClipShape::new(Shape::Sphere, centre(), n[3])
            }
            "box" => {
                count(&[6, 9])?;
                let mut s = ClipShape::new(Shape::Box, centre(), 1.0);
                s.scale = [n[3] * 0.5, n[4] * 0.5, n[5] * 0.5];
                s.rotation_deg = rotation(6);
                s
            }
            "cylinder" => {
                count(&[5, 8])?;
                let mut s = ClipShape::new(Shape::Cylinder, centre(), n[3]);
                s.scale[2] = n[4] * 0.5;
                s.rotation_deg = rotation(5);
                s
            }
            "torus" => {
                count(&[5, 8])?;
                if n[3] <= 0.0 {
                    return Err(format!(
                        "clip shape {spec:?}: the major radius must be positive"
                    ));
                }
                let mut s = ClipShape::new(Shape::Torus { tube: n[4] / n[3] }, centre(), n[3]);
                s.rotation_deg = rotation(5);
                s
            }
            other => {
                return Err(format!(
                    "unknown clip shape {other:?} (available: plane, sphere, box, cylinder, torus, mesh)"
                ));
            }
        };
        shape.mode = ClipMode::Carve;
        shape
            .check(0)
            .map_err(|e| format!("clip shape {spec:?}: {e}"))?;
        Ok(shape)
    }
}

fn numbers<'a>(spec: &str, parts: impl Iterator<Item = &'a str>) -> Result<Vec<f32>, String> {
    parts
        .filter(|p| !p.trim().is_empty())
        .map(|p| {
            p.trim()
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("clip shape {spec:?}: {p:?} is not a number"))
        })
        .collect()
}

/// Checks a list of shapes: count and every pose.
pub fn check_all(shapes: &[ClipShape]) -> Result<(), ClipError> {
    if shapes.len() > MAX_SHAPES {
        return Err(ClipError::TooMany {
            count: shapes.len(),
        });
    }
    shapes.iter().enumerate().try_for_each(|(i, s)| s.check(i))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cli_shapes_parse_with_their_sizes() {
        let s = ClipShape::parse("sphere:1,2,3,10").expect("sphere");
        assert_eq!((s.translation, s.scale), ([1.0, 2.0, 3.0], [10.0; 3]));
        let b = ClipShape::parse("box:0,0,0,10,20,30,0,90,0").expect("box");
        assert_eq!(
            (b.scale, b.rotation_deg),
            ([5.0, 10.0, 15.0], [0.0, 90.0, 0.0])
        );
        let c = ClipShape::parse("cylinder:0,0,0,5,40").expect("cylinder");
        assert_eq!(c.scale, [5.0, 5.0, 20.0]);
        let t = ClipShape::parse("torus:0,0,0,20,5").expect("torus");
        assert_eq!(t.shape, Shape::Torus { tube: 0.25 });
        let p = ClipShape::parse("plane:0,0,5,0,0,-1").expect("plane");
        // The plane's local +z (the removed side) is the given normal.
        let n = p.rotation() * Vec3::Z;
        assert!((n - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-5, "{n}");
        let m = ClipShape::parse("mesh:part.stl,1,2,3,0.5").expect("mesh");
        assert_eq!(
            m.shape,
            Shape::Mesh {
                path: "part.stl".into()
            }
        );
        assert_eq!(m.scale, [0.5; 3]);
    }

    #[test]
    fn bad_cli_shapes_say_what_is_wrong() {
        let err = |s: &str| ClipShape::parse(s).expect_err(s);
        assert!(err("sphere").contains("KIND:NUMBERS"));
        assert!(err("sphere:1,2,3").contains("takes [4] numbers"));
        assert!(err("sphere:1,2,3,x").contains("not a number"));
        assert!(err("sphere:1,2,3,NaN").contains("not a number"));
        assert!(err("sphere:0,0,0,-4").contains("positive"));
        assert!(err("plane:0,0,0,0,0,0").contains("normal is zero"));
        assert!(err("torus:0,0,0,10,12").contains("tube radius"));
        assert!(err("cone:0,0,0,1").contains("unknown clip shape"));
        let too_many = vec![ClipShape::new(Shape::Sphere, Vec3::ZERO, 1.0); MAX_SHAPES + 1];
        assert!(check_all(&too_many).is_err());
        assert!(check_all(&too_many[..MAX_SHAPES]).is_ok());
    }

    #[test]
    fn scene_json_round_trips() {
        let s = ClipShape {
            mode: ClipMode::Probe,
            ..ClipShape::new(Shape::Torus { tube: 0.3 }, Vec3::new(1.0, 2.0, 3.0), 7.0)
        };
        let text = serde_json::to_string(&s).expect("json");
        assert!(
            text.contains("\"type\":\"torus\"") && text.contains("\"probe\""),
            "{text}"
        );
        assert_eq!(serde_json::from_str::<ClipShape>(&text).expect("parse"), s);
        assert!(serde_json::from_str::<ClipShape>(r#"{"shape":{"type":"cone"},"translation":[0,0,0],"rotation_deg":[0,0,0],"scale":[1,1,1]}"#).is_err());
    }
}
