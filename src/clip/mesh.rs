//! Closed triangle meshes for clipping: the built-in shapes and OBJ/STL files.
//!
//! Shadow-test clipping (CAO paper §3.2) decides "inside" from the front and back faces
//! a clipping camera sees, so a mesh must be closed and consistently wound (every edge
//! shared by exactly two triangles in opposite directions) with its faces pointing
//! outwards. [`TriMesh::validate`] checks all of that and turns inward-facing meshes
//! around.

use glam::Vec3;
use std::collections::HashMap;
use std::path::Path;

/// Why a mesh cannot be used for clipping.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: {message}")]
    File { path: String, message: String },
    #[error("{what}: the mesh has no triangles")]
    Empty { what: String },
    #[error("{what}: the mesh has zero extent along at least one axis ({extent:?} mm)")]
    Flat { what: String, extent: [f32; 3] },
    #[error("{what}: vertex {index} is not finite")]
    NotFinite { what: String, index: usize },
    #[error(
        "{what}: the mesh is not closed ({open} edges belong to one triangle only, {over} to more than two); \
         clipping needs a closed surface"
    )]
    Open {
        what: String,
        open: usize,
        over: usize,
    },
    #[error(
        "{what}: the triangles are not wound consistently ({count} edges run the same way twice)"
    )]
    Winding { what: String, count: usize },
}

/// An indexed triangle mesh; triangles wind counter-clockwise seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    pub vertices: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Axis-aligned bounds (min, max).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.vertices.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), v| (lo.min(*v), hi.max(*v)),
        )
    }

    /// Signed volume (positive when the faces point outwards).
    pub fn signed_volume(&self) -> f32 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// The mesh scaled per axis.
    pub fn scaled(&self, scale: Vec3) -> TriMesh {
        TriMesh {
            vertices: self.vertices.iter().map(|v| *v * scale).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Checks the mesh is usable for clipping: finite, non-flat, closed and consistently
    /// wound. Degenerate (zero-area) triangles are dropped first; an inside-out mesh is
    /// turned around. `what` names the mesh in errors.
    pub fn validate(mut self, what: &str) -> Result<TriMesh, MeshError> {
        let what = what.to_owned();
        if let Some(index) = self.vertices.iter().position(|v| !v.is_finite()) {
            return Err(MeshError::NotFinite { what, index });
        }
        let n = self.vertices.len() as u32;
        self.triangles.retain(|t| {
            t.iter().all(|&i| i < n) && t[0] != t[1] && t[1] != t[2] && t[0] != t[2] && {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                (b - a).cross(c - a).length_squared() > 0.0
            }
        });
        if self.triangles.is_empty() {
            return Err(MeshError::Empty { what });
        }
        let (lo, hi) = self.bounds();
        let extent = (hi - lo).to_array();
        if extent.iter().any(|&e| e <= 0.0 || !e.is_finite()) {
            return Err(MeshError::Flat { what, extent });
        }
        // Each directed edge must appear once and its reverse once.
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        let mut open = 0;
        let mut over = 0;
        let mut same_way = 0;
        for (&(a, b), &count) in &directed {
            let back = directed.get(&(b, a)).copied().unwrap_or(0);
            if count > 1 {
                same_way += 1;
            }
            match count + back {
                1 => open += 1,
                2 => {}
                _ => over += 1,
            }
        }
        if open > 0 || over > 0 {
            return Err(MeshError::Open { what, open, over });
        }
        if same_way > 0 {
            return Err(MeshError::Winding {
                what,
                count: same_way,
            });
        }
        if self.signed_volume() < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
        Ok(self)
    }
}

/// Merges vertices at identical positions (STL and some OBJ exporters repeat them).
fn welded(positions: &[Vec3], triangles: &[[u32; 3]]) -> TriMesh {
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut remap = Vec::with_capacity(positions.len());
    for p in positions {
        let key = p.to_array().map(f32::to_bits);
        let i = *index.entry(key).or_insert_with(|| {
            vertices.push(*p);
            (vertices.len() - 1) as u32
        });
        remap.push(i);
    }
    TriMesh {
        vertices,
        triangles: triangles
            .iter()
            .map(|t| t.map(|i| remap.get(i as usize).copied().unwrap_or(u32::MAX)))
            .collect(),
    }
}

/// Loads an OBJ or STL file (by extension) as a validated clipping mesh. Coordinates are
/// taken as millimetres.
pub fn load(path: &Path) -> Result<TriMesh, MeshError> {
    let name = path.display().to_string();
    let fail = |message: String| MeshError::File {
        path: name.clone(),
        message,
    };
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let mesh = match ext.as_str() {
        "obj" => {
            let (models, _) = tobj::load_obj(
                path,
                &tobj::LoadOptions {
                    triangulate: true,
                    single_index: false,
                    ..Default::default()
                },
            )
            .map_err(|e| fail(format!("not a readable OBJ file: {e}")))?;
            let mut positions = Vec::new();
            let mut triangles = Vec::new();
            for m in models {
                let base = positions.len() as u32;
                positions.extend(
                    m.mesh
                        .positions
                        .chunks_exact(3)
                        .map(|c| Vec3::new(c[0], c[1], c[2])),
                );
                triangles.extend(
                    m.mesh
                        .indices
                        .chunks_exact(3)
                        .map(|c| [c[0] + base, c[1] + base, c[2] + base]),
                );
            }
            welded(&positions, &triangles)
        }
        "stl" => {
            let mut file = std::fs::File::open(path).map_err(|e| fail(e.to_string()))?;
            let stl = stl_io::read_stl(&mut file)
                .map_err(|e| fail(format!("not a readable STL file: {e}")))?;
            let positions: Vec<Vec3> = stl.vertices.iter().map(|v| Vec3::from(v.0)).collect();
            let triangles: Vec<[u32; 3]> = stl
                .faces
                .iter()
                .map(|f| f.vertices.map(|i| i as u32))
                .collect();
            welded(&positions, &triangles)
        }
        _ => {
            return Err(fail(
                "unknown mesh format (expected .obj or .stl)".to_owned(),
            ));
        }
    };
    mesh.validate(&name)
}

/// Unit sphere (radius 1) as a UV sphere with `rings` latitude bands.
pub fn sphere(rings: u32, segments: u32) -> TriMesh {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut vertices = vec![Vec3::Z];
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            vertices.push(Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ));
        }
    }
    vertices.push(-Vec3::Z);
    let south = vertices.len() as u32 - 1;
    let ring = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut triangles = Vec::new();
    for s in 0..segments {
        triangles.push([0, ring(1, s), ring(1, s + 1)]);
        triangles.push([south, ring(rings - 1, s + 1), ring(rings - 1, s)]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            let (a, b, c, d) = (
                ring(r, s),
                ring(r, s + 1),
                ring(r + 1, s),
                ring(r + 1, s + 1),
            );
            triangles.push([a, c, d]);
            triangles.push([a, d, b]);
        }
    }
    TriMesh {
        vertices,
        triangles,
    }
}

/// Axis-aligned box `[lo, hi]`.
pub fn cuboid(lo: Vec3, hi: Vec3) -> TriMesh {
    let vertices = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    // Two triangles per face, counter-clockwise seen from outside.
    let quads = [
        [0, 2, 3, 1], // z = lo
        [4, 5, 7, 6], // z = hi
        [0, 1, 5, 4], // y = lo
        [2, 6, 7, 3], // y = hi
        [0, 4, 6, 2], // x = lo
        [1, 3, 7, 5], // x = hi
    ];
    let triangles = quads
        .iter()
        .flat_map(|q: &[u32; 4]| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    TriMesh {
        vertices,
        triangles,
    }
}

/// Unit cylinder: radius 1 around z, z in [-1, 1].
pub fn cylinder(segments: u32) -> TriMesh {
    let segments = segments.max(3);
    let mut vertices = vec![Vec3::new(0.0, 0.0, -1.0), Vec3::new(0.0, 0.0, 1.0)];
    for z in [-1.0, 1.0] {
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            vertices.push(Vec3::new(phi.cos(), phi.sin(), z));
        }
    }
    let bottom = |s: u32| 2 + s % segments;
    let top = |s: u32| 2 + segments + s % segments;
    let mut triangles = Vec::new();
    for s in 0..segments {
        triangles.push([0, bottom(s + 1), bottom(s)]);
        triangles.push([1, top(s), top(s + 1)]);
        triangles.push([bottom(s), bottom(s + 1), top(s + 1)]);
        triangles.push([bottom(s), top(s + 1), top(s)]);
    }
    TriMesh {
        vertices,
        triangles,
    }
}

/// Torus around the y axis (its ring in the xz plane): major radius 1, tube radius
/// `tube` (< 1). Seen by the clipping camera (down −z) it is edge-on, where a view ray
/// crosses the tube twice: the case the second depth-peeling layer exists for.
pub fn torus(tube: f32, major_segments: u32, minor_segments: u32) -> TriMesh {
    let (nu, nv) = (major_segments.max(3), minor_segments.max(3));
    let mut vertices = Vec::with_capacity((nu * nv) as usize);
    for u in 0..nu {
        let a = std::f32::consts::TAU * u as f32 / nu as f32;
        for v in 0..nv {
            let b = std::f32::consts::TAU * v as f32 / nv as f32;
            let r = 1.0 + tube * b.cos();
            vertices.push(Vec3::new(r * a.cos(), tube * b.sin(), r * a.sin()));
        }
    }
    let at = |u: u32, v: u32| (u % nu) * nv + v % nv;
    let mut triangles = Vec::new();
    for u in 0..nu {
        for v in 0..nv {
            let (a, b, c, d) = (at(u, v), at(u + 1, v), at(u + 1, v + 1), at(u, v + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    TriMesh {
        vertices,
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checked(m: TriMesh) -> TriMesh {
        m.validate("test").unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn built_in_shapes_are_closed_outward_and_the_right_size() {
        let pi = std::f32::consts::PI;
        let cases = [
            (checked(sphere(48, 96)), 4.0 / 3.0 * pi, 0.01),
            (checked(cuboid(Vec3::NEG_ONE, Vec3::ONE)), 8.0, 1e-6),
            (checked(cylinder(96)), 2.0 * pi, 0.01),
            // Torus volume 2π²Rr².
            (checked(torus(0.3, 96, 48)), 2.0 * pi * pi * 0.09, 0.01),
        ];
        for (m, volume, tol) in cases {
            let v = m.signed_volume();
            assert!((v - volume).abs() / volume < tol, "volume {v} vs {volume}");
        }
    }

    #[test]
    fn inside_out_meshes_are_turned_around() {
        let mut m = cuboid(Vec3::ZERO, Vec3::ONE);
        for t in &mut m.triangles {
            t.swap(1, 2);
        }
        assert!(m.signed_volume() < 0.0);
        assert!(checked(m).signed_volume() > 0.0);
    }

    #[test]
    fn broken_meshes_are_refused_with_the_reason() {
        let mut open = cuboid(Vec3::ZERO, Vec3::ONE);
        open.triangles.pop();
        let e = open.validate("open.stl").expect_err("open").to_string();
        assert!(e.contains("open.stl") && e.contains("not closed"), "{e}");

        let mut wound = cuboid(Vec3::ZERO, Vec3::ONE);
        wound.triangles[0].swap(1, 2);
        let e = wound.validate("w").expect_err("winding").to_string();
        assert!(e.contains("not closed") || e.contains("wound"), "{e}");

        let flat = TriMesh {
            vertices: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::X + Vec3::Y],
            triangles: vec![[0, 1, 2], [1, 3, 2], [0, 2, 1], [1, 2, 3]],
        };
        let e = flat.validate("flat").expect_err("flat").to_string();
        assert!(e.contains("zero extent"), "{e}");

        let mut nan = cuboid(Vec3::ZERO, Vec3::ONE);
        nan.vertices[3].y = f32::NAN;
        assert!(
            nan.validate("nan")
                .expect_err("nan")
                .to_string()
                .contains("not finite")
        );

        let degenerate = TriMesh {
            vertices: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            triangles: vec![[0, 1, 2], [0, 0, 1]],
        };
        let e = degenerate
            .validate("d")
            .expect_err("degenerate")
            .to_string();
        assert!(e.contains("no triangles"), "{e}");

        let out_of_range = TriMesh {
            vertices: vec![Vec3::ZERO],
            triangles: vec![[0, 5, 9]],
        };
        assert!(out_of_range.validate("r").is_err());
    }

    #[test]
    fn obj_and_stl_files_load_and_bad_ones_fail_clearly() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cube = cuboid(Vec3::splat(-2.0), Vec3::splat(3.0));
        // OBJ (1-based indices).
        let mut obj = String::new();
        for v in &cube.vertices {
            obj += &format!("v {} {} {}\n", v.x, v.y, v.z);
        }
        for t in &cube.triangles {
            obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        let obj_path = dir.path().join("cube.obj");
        std::fs::write(&obj_path, obj).expect("write");
        let m = load(&obj_path).unwrap_or_else(|e| panic!("{e}"));
        assert!((m.signed_volume() - 125.0).abs() < 1e-3);
        // Binary STL: every triangle carries its own vertices; they are welded.
        let stl: Vec<stl_io::Triangle> = cube
            .triangles
            .iter()
            .map(|t| stl_io::Triangle {
                normal: stl_io::Normal::new([0.0; 3]),
                vertices: t.map(|i| stl_io::Vertex::new(cube.vertices[i as usize].to_array())),
            })
            .collect();
        let stl_path = dir.path().join("cube.stl");
        let mut f = std::fs::File::create(&stl_path).expect("create");
        stl_io::write_stl(&mut f, stl.iter()).expect("write stl");
        drop(f);
        let m = load(&stl_path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.vertices.len(), 8);
        assert!((m.signed_volume() - 125.0).abs() < 1e-3);
        // An open OBJ, garbage, a missing file and an unknown extension.
        let open_path = dir.path().join("open.obj");
        std::fs::write(
            &open_path,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n",
        )
        .expect("write");
        let e = load(&open_path).expect_err("open").to_string();
        assert!(e.contains("open.obj") && e.contains("not closed"), "{e}");
        let junk = dir.path().join("junk.stl");
        std::fs::write(&junk, b"solid x\nfacet garbage").expect("write");
        assert!(
            load(&junk)
                .expect_err("junk")
                .to_string()
                .contains("junk.stl")
        );
        let missing = dir.path().join("missing.obj");
        assert!(
            load(&missing)
                .expect_err("missing")
                .to_string()
                .contains("missing.obj")
        );
        let e = load(&dir.path().join("mesh.ply"))
            .expect_err("ply")
            .to_string();
        assert!(e.contains(".obj or .stl"), "{e}");
    }
}
