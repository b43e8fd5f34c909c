//! Slices in patient orientation: the axial, coronal and sagittal planes a radiologist
//! reads, cut from a volume of any orientation.
//!
//! A [`SliceGeometry`] lays a grid on the patient's axes (RAS, mm) over the volume: for
//! a volume whose voxel axes run along the patient's axes (any permutation and flips)
//! it is the voxel grid itself, so every slice holds one pixel per voxel; an oblique
//! acquisition is resampled onto the patient axes at its finest spacing, as Slicer shows
//! it by default ([`Plane::Patient`]), or shown in its own planes
//! ([`Plane::Acquisition`], as nibabel's `as_closest_canonical` orders it). In-plane
//! spacings that differ are resampled to the finer one, so pixels are square.
//!
//! Images follow the reading-room conventions: axial slices seen from the feet and
//! coronal slices from the front, with the patient's right on the image's left
//! ([`Convention::Radiological`], PACS and Slicer; [`Convention::Neurological`] mirrors
//! left and right), anterior resp. superior at the top; sagittal slices with anterior on
//! the left and superior at the top.
//!
//! Pixel `(column c, row r)` of a slice at grid index `k` is the world point
//! `min + u·c·f + v·r·f + n·k·s` (with `u`, `v` the image axes' world directions after
//! the flips, `f` the pixel size); its nearest voxel is `floor(t + ½)` of the continuous
//! voxel index `t = A⁻¹(p − o)`, and outside the volume it has no value.

mod annotate;

pub use annotate::{annotate, draw_text, orientation_marker, scale_bar_length};

use crate::texels::segments::ClassLook;
use crate::volume::Volume;
use glam::{DMat3, DVec3};

/// A slice's plane, named by its normal's world axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SliceAxis {
    /// Normal S/I (world z): seen from the feet.
    Axial,
    /// Normal A/P (world y): seen from the front.
    Coronal,
    /// Normal R/L (world x): seen from the patient's left.
    Sagittal,
}

impl SliceAxis {
    pub const ALL: [SliceAxis; 3] = [SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal];

    /// The world axis (0 = R, 1 = A, 2 = S) normal to the plane.
    pub fn normal(self) -> usize {
        match self {
            SliceAxis::Axial => 2,
            SliceAxis::Coronal => 1,
            SliceAxis::Sagittal => 0,
        }
    }

    /// The world axes along the image's columns and rows.
    pub fn in_plane(self) -> [usize; 2] {
        match self {
            SliceAxis::Axial => [0, 1],
            SliceAxis::Coronal => [0, 2],
            SliceAxis::Sagittal => [1, 2],
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SliceAxis::Axial => "axial",
            SliceAxis::Coronal => "coronal",
            SliceAxis::Sagittal => "sagittal",
        }
    }

    /// Parses `axial`, `coronal`, `sagittal` (or their first letter).
    pub fn parse(s: &str) -> Result<SliceAxis, String> {
        match s.to_ascii_lowercase().as_str() {
            "axial" | "a" | "transverse" => Ok(SliceAxis::Axial),
            "coronal" | "c" => Ok(SliceAxis::Coronal),
            "sagittal" | "s" => Ok(SliceAxis::Sagittal),
            _ => Err(format!(
                "unknown slice axis {s:?}: expected axial, coronal or sagittal"
            )),
        }
    }
}

/// How the central area is divided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Layout {
    /// Axial and 3-D above, coronal and sagittal below.
    #[default]
    Quad,
    /// The 3-D view alone.
    ThreeD,
    /// The 3-D view large, the three slices stacked beside it.
    OnePlusThree,
}

impl Layout {
    pub const ALL: [Layout; 3] = [Layout::Quad, Layout::ThreeD, Layout::OnePlusThree];

    /// Parses `2x2`, `3d` or `1+3`.
    pub fn parse(s: &str) -> Result<Layout, String> {
        match s.to_ascii_lowercase().as_str() {
            "2x2" | "quad" => Ok(Layout::Quad),
            "3d" => Ok(Layout::ThreeD),
            "1+3" => Ok(Layout::OnePlusThree),
            _ => Err(format!("{s:?}: expected 2x2, 3d or 1+3")),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Layout::Quad => "2×2: axial, 3-D, coronal, sagittal",
            Layout::ThreeD => "3-D only",
            Layout::OnePlusThree => "1 + 3: 3-D and three slices",
        }
    }

    /// The next layout (the viewer's Ctrl+L).
    pub fn next(self) -> Layout {
        match self {
            Layout::Quad => Layout::ThreeD,
            Layout::ThreeD => Layout::OnePlusThree,
            Layout::OnePlusThree => Layout::Quad,
        }
    }
}

/// One pane of a layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pane {
    ThreeD,
    Slice(SliceAxis),
}

/// Gap between panes (points or pixels).
pub const PANE_GAP: f32 = 2.0;

impl Layout {
    /// The panes of a `[left, top, right, bottom]` rectangle and theirs.
    pub fn panes(self, r: [f32; 4]) -> Vec<(Pane, [f32; 4])> {
        let g = PANE_GAP / 2.0;
        let columns = |r: [f32; 4], f: f32| {
            let x = r[0] + (r[2] - r[0]) * f;
            ([r[0], r[1], x - g, r[3]], [x + g, r[1], r[2], r[3]])
        };
        let rows = |r: [f32; 4], f: f32| {
            let y = r[1] + (r[3] - r[1]) * f;
            ([r[0], r[1], r[2], y - g], [r[0], y + g, r[2], r[3]])
        };
        match self {
            Layout::ThreeD => vec![(Pane::ThreeD, r)],
            Layout::Quad => {
                let (top, bottom) = rows(r, 0.5);
                let (tl, tr) = columns(top, 0.5);
                let (bl, br) = columns(bottom, 0.5);
                vec![
                    (Pane::Slice(SliceAxis::Axial), tl),
                    (Pane::ThreeD, tr),
                    (Pane::Slice(SliceAxis::Coronal), bl),
                    (Pane::Slice(SliceAxis::Sagittal), br),
                ]
            }
            Layout::OnePlusThree => {
                let (big, side) = columns(r, 0.7);
                let (a, rest) = rows(side, 1.0 / 3.0);
                let (c, s) = rows(rest, 0.5);
                vec![
                    (Pane::ThreeD, big),
                    (Pane::Slice(SliceAxis::Axial), a),
                    (Pane::Slice(SliceAxis::Coronal), c),
                    (Pane::Slice(SliceAxis::Sagittal), s),
                ]
            }
        }
    }
}

/// Where a slice image of `size` pixels sits in a pane `[left, top, right, bottom]`:
/// scaled to fit (square pixels) and centred; returns its rectangle and the scale.
pub fn fit(size: [usize; 2], pane: [f32; 4]) -> ([f32; 4], f32) {
    let (w, h) = (pane[2] - pane[0], pane[3] - pane[1]);
    let scale = (w / size[0] as f32).min(h / size[1] as f32).max(1e-3);
    let (iw, ih) = (size[0] as f32 * scale, size[1] as f32 * scale);
    let (x, y) = (pane[0] + (w - iw) / 2.0, pane[1] + (h - ih) / 2.0);
    ([x, y, x + iw, y + ih], scale)
}

/// The panes of `layout` in one `width`×`height` image, as the viewer lays them out:
/// `three_d` (rendered at its pane's size, [`Layout::three_d_size`]) and the slices
/// (`(axis, [w, h], rgb)`) scaled to fit their panes with the nearest pixel, on black.
pub fn compose(
    layout: Layout,
    width: u32,
    height: u32,
    three_d: &crate::render::Image,
    slices: &[(SliceAxis, [usize; 2], Vec<u8>)],
) -> crate::render::Image {
    let mut out = crate::render::Image {
        width,
        height,
        pixels: vec![[0, 0, 0, 255]; (width * height) as usize],
    };
    for (pane, r) in layout.panes([0.0, 0.0, width as f32, height as f32]) {
        let [x0, y0, x1, y1] = pixel_rect(r);
        match pane {
            Pane::ThreeD => {
                for y in y0..y1.min(y0 + three_d.height) {
                    for x in x0..x1.min(x0 + three_d.width) {
                        out.pixels[(y * width + x) as usize] =
                            three_d.pixels[((y - y0) * three_d.width + (x - x0)) as usize];
                    }
                }
            }
            Pane::Slice(axis) => {
                let Some((_, size, rgb)) = slices.iter().find(|(a, _, _)| *a == axis) else {
                    continue;
                };
                let (img, scale) = fit(*size, [x0 as f32, y0 as f32, x1 as f32, y1 as f32]);
                for y in y0..y1 {
                    for x in x0..x1 {
                        let u = ((x as f32 + 0.5 - img[0]) / scale).floor();
                        let v = ((y as f32 + 0.5 - img[1]) / scale).floor();
                        if u < 0.0 || v < 0.0 || u >= size[0] as f32 || v >= size[1] as f32 {
                            continue;
                        }
                        let i = 3 * (v as usize * size[0] + u as usize);
                        out.pixels[(y * width + x) as usize] =
                            [rgb[i], rgb[i + 1], rgb[i + 2], 255];
                    }
                }
            }
        }
    }
    out
}

/// A pane's whole pixels: `[x0, y0, x1, y1)`.
fn pixel_rect(r: [f32; 4]) -> [u32; 4] {
    r.map(|v| v.round().max(0.0) as u32)
}

impl Layout {
    /// The 3-D pane's size in whole pixels in a `width`×`height` image.
    pub fn three_d_size(self, width: u32, height: u32) -> (u32, u32) {
        self.panes([0.0, 0.0, width as f32, height as f32])
            .into_iter()
            .find(|(p, _)| *p == Pane::ThreeD)
            .map_or((width, height), |(_, r)| {
                let [x0, y0, x1, y1] = pixel_rect(r);
                ((x1 - x0).max(1), (y1 - y0).max(1))
            })
    }
}

/// Which side of the patient is on the image's left.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Convention {
    /// The patient's right on the image's left (PACS, Slicer).
    #[default]
    Radiological,
    /// The patient's left on the image's left.
    Neurological,
}

/// The planes slices are cut in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Plane {
    /// The patient's axes: oblique acquisitions are resampled onto them.
    #[default]
    Patient,
    /// The acquisition's own planes (voxel axes ordered and flipped towards RAS, never
    /// resampled): what `as_closest_canonical` gives.
    Acquisition,
}

/// How a pixel reads the volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// The voxel whose centre is nearest.
    #[default]
    Nearest,
    /// Trilinear between the eight nearest voxel centres.
    Linear,
}

/// The world letter at each end of a world axis: (negative end, positive end).
const LETTERS: [(char, char); 3] = [('L', 'R'), ('P', 'A'), ('I', 'S')];

/// The patient-aligned grid slices are cut from, over one volume.
#[derive(Debug, Clone, PartialEq)]
pub struct SliceGeometry {
    /// World position (mm) of grid point (0, 0, 0): the lowest corner.
    pub min: DVec3,
    /// Grid spacing along R, A, S (mm).
    pub spacing: [f64; 3],
    /// Grid points along R, A, S.
    pub dims: [usize; 3],
    /// World → continuous voxel index of the volume.
    to_voxel: DMat3,
    /// The volume's voxel (0, 0, 0) in world mm.
    origin: DVec3,
    volume_dims: [usize; 3],
}

impl SliceGeometry {
    /// The grid over `volume` for `plane`.
    pub fn new(volume: &Volume, plane: Plane) -> SliceGeometry {
        let o = &volume.orientation;
        let (linear, origin) = match plane {
            Plane::Patient => (o.linear, o.offset),
            Plane::Acquisition => acquisition_affine(volume),
        };
        let cols = [linear.x_axis, linear.y_axis, linear.z_axis];
        let aligned = is_axis_aligned(&cols);
        let finest = cols
            .iter()
            .map(|c| c.length())
            .fold(f64::INFINITY, f64::min);
        let last: [f64; 3] = std::array::from_fn(|i| volume.dims[i].saturating_sub(1) as f64);
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for corner in 0..8 {
            let idx = DVec3::new(
                if corner & 1 != 0 { last[0] } else { 0.0 },
                if corner & 2 != 0 { last[1] } else { 0.0 },
                if corner & 4 != 0 { last[2] } else { 0.0 },
            );
            let p = linear * idx + origin;
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let spacing: [f64; 3] = std::array::from_fn(|world| {
            if aligned {
                // The voxel axis along this world axis keeps its own spacing.
                cols.iter()
                    .find(|c| along(c, world))
                    .map_or(finest, |c| c[world].abs())
            } else {
                finest
            }
        });
        let dims = std::array::from_fn(|i| points_along(hi[i] - lo[i], spacing[i]));
        SliceGeometry {
            min: lo,
            spacing,
            dims,
            to_voxel: linear.inverse(),
            origin,
            volume_dims: volume.dims,
        }
    }

    /// How many slices there are along `axis`.
    pub fn count(&self, axis: SliceAxis) -> usize {
        self.dims[axis.normal()]
    }

    /// The slice index nearest to world point `p` (clamped into the grid).
    pub fn index_at(&self, axis: SliceAxis, p: DVec3) -> usize {
        let n = axis.normal();
        let t = ((p[n] - self.min[n]) / self.spacing[n] + 0.5).floor();
        t.clamp(0.0, self.dims[n].saturating_sub(1) as f64) as usize
    }

    /// The world coordinate (mm along the axis' normal) of slice `index`.
    pub fn position(&self, axis: SliceAxis, index: usize) -> f64 {
        let n = axis.normal();
        self.min[n] + index as f64 * self.spacing[n]
    }

    /// The middle slice.
    pub fn middle(&self, axis: SliceAxis) -> usize {
        self.count(axis) / 2
    }

    /// The world point at the centre of the grid.
    pub fn centre(&self) -> DVec3 {
        DVec3::from_array(std::array::from_fn(|i| {
            self.min[i] + (self.dims[i] / 2) as f64 * self.spacing[i]
        }))
    }

    /// Pixel size (mm) of `axis`' images: the finer of its two in-plane spacings.
    pub fn pixel_mm(&self, axis: SliceAxis) -> f64 {
        let [u, v] = axis.in_plane();
        self.spacing[u].min(self.spacing[v])
    }

    /// Image size (width, height) in pixels of a slice along `axis`.
    pub fn image_size(&self, axis: SliceAxis) -> [usize; 2] {
        let f = self.pixel_mm(axis);
        axis.in_plane().map(|w| {
            let extent = (self.dims[w].saturating_sub(1)) as f64 * self.spacing[w];
            points_along(extent, f)
        })
    }

    /// For the image's columns and rows: the world axis, and whether the pixel index runs
    /// towards that axis' negative end (L, P, I).
    fn image_axes(&self, axis: SliceAxis, convention: Convention) -> [(usize, bool); 2] {
        let [u, v] = axis.in_plane();
        let columns_flip = match axis {
            // The patient's right on the left: columns run R → L.
            SliceAxis::Axial | SliceAxis::Coronal => convention == Convention::Radiological,
            // Anterior on the left: columns run A → P.
            SliceAxis::Sagittal => true,
        };
        // Anterior (axial) or superior (coronal, sagittal) at the top.
        [(u, columns_flip), (v, true)]
    }

    /// The world point at the centre of pixel (column, row) of slice `index` (the pixel
    /// coordinates may be fractional, for the pointer).
    pub fn pixel_to_world(
        &self,
        axis: SliceAxis,
        convention: Convention,
        index: usize,
        pixel: [f64; 2],
    ) -> DVec3 {
        let size = self.image_size(axis);
        let f = self.pixel_mm(axis);
        let mut p = self.min;
        p[axis.normal()] = self.position(axis, index);
        for (k, (w, flip)) in self.image_axes(axis, convention).into_iter().enumerate() {
            let along = if flip {
                (size[k] - 1) as f64 - pixel[k]
            } else {
                pixel[k]
            };
            p[w] = self.min[w] + along * f;
        }
        p
    }

    /// The (column, row) at which world point `p` appears in `axis`' images.
    pub fn world_to_pixel(&self, axis: SliceAxis, convention: Convention, p: DVec3) -> [f64; 2] {
        let size = self.image_size(axis);
        let f = self.pixel_mm(axis);
        let axes = self.image_axes(axis, convention);
        std::array::from_fn(|k| {
            let (w, flip) = axes[k];
            let along = (p[w] - self.min[w]) / f;
            if flip {
                (size[k] - 1) as f64 - along
            } else {
                along
            }
        })
    }

    /// The letters at the image's left, right, top and bottom edges.
    pub fn edge_letters(&self, axis: SliceAxis, convention: Convention) -> [char; 4] {
        let [(u, uf), (v, vf)] = self.image_axes(axis, convention);
        let ends = |w: usize, flip: bool| {
            let (neg, pos) = LETTERS[w];
            if flip { (pos, neg) } else { (neg, pos) }
        };
        let (left, right) = ends(u, uf);
        let (top, bottom) = ends(v, vf);
        [left, right, top, bottom]
    }

    /// The continuous voxel index of world point `p`.
    pub fn voxel_at(&self, p: DVec3) -> DVec3 {
        self.to_voxel * (p - self.origin)
    }

    /// The voxel nearest to world point `p`, if it lies in the volume.
    pub fn nearest_voxel(&self, p: DVec3) -> Option<[usize; 3]> {
        let t = self.voxel_at(p);
        let mut ijk = [0usize; 3];
        for i in 0..3 {
            let r = (t[i] + 0.5).floor();
            if r.is_nan() || r < 0.0 || r >= self.volume_dims[i] as f64 {
                return None;
            }
            ijk[i] = r as usize;
        }
        Some(ijk)
    }

    /// Cuts slice `index` along `axis` out of `volume` (the volume this geometry was made
    /// for): physical values, `NaN` outside the volume.
    pub fn cut(
        &self,
        volume: &Volume,
        axis: SliceAxis,
        convention: Convention,
        index: usize,
        sampling: Sampling,
    ) -> Slice {
        let [w, h] = self.image_size(axis);
        let mut values = Vec::with_capacity(w * h);
        let mut voxels = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let p = self.pixel_to_world(axis, convention, index, [c as f64, r as f64]);
                let nearest = self.nearest_voxel(p);
                let value = match sampling {
                    Sampling::Nearest => nearest.and_then(|[x, y, z]| volume.value(x, y, z)),
                    Sampling::Linear => nearest.and(trilinear(volume, self.voxel_at(p))),
                };
                values.push(value.map_or(f32::NAN, |v| v as f32));
                voxels.push(nearest.map(|[x, y, z]| x + volume.dims[0] * (y + volume.dims[1] * z)));
            }
        }
        Slice {
            width: w,
            height: h,
            values,
            voxels,
        }
    }
}

/// The 3-D view's space (mm from the volume's centre along its voxel axes, as the ray
/// caster and clip shapes use it) → the patient's world (RAS mm, by the affine).
pub fn volume_to_world(volume: &Volume, p: glam::Vec3) -> DVec3 {
    let o = &volume.orientation;
    let ijk = DVec3::from_array(std::array::from_fn(|i| {
        let s = f64::from(volume.spacing[i]);
        (f64::from(p[i]) + volume.dims[i] as f64 * s / 2.0) / s - 0.5
    }));
    o.linear * ijk + o.offset
}

/// The inverse of [`volume_to_world`].
pub fn world_to_volume(volume: &Volume, w: DVec3) -> glam::Vec3 {
    let o = &volume.orientation;
    let ijk = o.linear.inverse() * (w - o.offset);
    glam::Vec3::from_array(std::array::from_fn(|i| {
        let s = f64::from(volume.spacing[i]);
        ((ijk[i] + 0.5) * s - volume.dims[i] as f64 * s / 2.0) as f32
    }))
}

/// One slice's pixels, row by row from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    pub width: usize,
    pub height: usize,
    /// Physical value of each pixel; `NaN` outside the volume.
    pub values: Vec<f32>,
    /// Each pixel's nearest voxel (index into the volume, x fastest), for overlays.
    pub voxels: Vec<Option<usize>>,
}

impl Slice {
    /// Greys of the window's linear ramp: `floor(clamp((v − lo) / (hi − lo), 0, 1) · 255 + ½)`
    /// with `lo, hi = level ∓ window/2` (black outside the volume).
    pub fn greys(&self, window: f64, level: f64) -> Vec<u8> {
        self.values
            .iter()
            .map(|&v| grey(v as f64, window, level))
            .collect()
    }
}

/// A segmentation drawn over a slice: each voxel's class and the classes' looks (from
/// [`crate::labels::style`]).
#[derive(Debug, Clone, Copy)]
pub struct LabelOverlay<'a> {
    /// The class of each voxel of the volume (x fastest); class 0 is "in no segment".
    pub classes: &'a [u16],
    pub looks: &'a [ClassLook],
    /// How much of a segment's colour covers the grey, 0 to 1.
    pub opacity: f32,
    /// Only the segments' borders in the slice, drawn opaque.
    pub outline: bool,
}

impl<'a> LabelOverlay<'a> {
    /// The segments' colours' share of the grey unless asked otherwise (`volao slice
    /// --label-opacity`, the viewer's slider, `volao render --layout`'s slices).
    pub const DEFAULT_OPACITY: f32 = 0.5;

    /// The overlay of a segmentation prepared for rendering (its classes on the volume's
    /// grid and their looks; the looks' cuts play no part in a slice).
    pub fn of(
        segments: &'a crate::texels::segments::SegmentTexels,
        opacity: f32,
        outline: bool,
    ) -> Self {
        LabelOverlay {
            classes: &segments.classes,
            looks: &segments.table,
            opacity,
            outline,
        }
    }
}

impl Slice {
    /// RGB pixels: the window's greys, with `overlay`'s segments blended over them.
    pub fn rgb(&self, window: f64, level: f64, overlay: Option<&LabelOverlay>) -> Vec<u8> {
        let mut out: Vec<u8> = self
            .greys(window, level)
            .into_iter()
            .flat_map(|g| [g, g, g])
            .collect();
        let Some(o) = overlay else {
            return out;
        };
        let class = |i: usize| self.voxels[i].map_or(0, |v| o.classes.get(v).copied().unwrap_or(0));
        let (w, h) = (self.width, self.height);
        for r in 0..h {
            for c in 0..w {
                let i = r * w + c;
                let k = class(i);
                let look = match o.looks.get(usize::from(k)) {
                    Some(l) if k != 0 && l.opacity > 0.0 => l,
                    _ => continue,
                };
                let alpha = if o.outline {
                    let border = [(0, -1), (0, 1), (-1, 0), (1, 0)].iter().any(|&(dc, dr)| {
                        let (cc, rr) = (c as isize + dc, r as isize + dr);
                        cc < 0
                            || rr < 0
                            || cc >= w as isize
                            || rr >= h as isize
                            || class(rr as usize * w + cc as usize) != k
                    });
                    if !border {
                        continue;
                    }
                    1.0
                } else {
                    o.opacity * look.opacity
                };
                for (ch, &col) in out[3 * i..3 * i + 3].iter_mut().zip(&look.color) {
                    *ch = (*ch as f32 * (1.0 - alpha) + col as f32 * alpha).round() as u8;
                }
            }
        }
        out
    }
}

/// The grey of value `v` in a window (NaN: black).
pub fn grey(v: f64, window: f64, level: f64) -> u8 {
    if v.is_nan() {
        return 0;
    }
    let lo = level - window / 2.0;
    let t = if window > 0.0 {
        ((v - lo) / window).clamp(0.0, 1.0)
    } else if v >= level {
        1.0
    } else {
        0.0
    };
    (t * 255.0 + 0.5).floor() as u8
}

/// Grid points spanning `extent` mm at `step` (both ends included).
fn points_along(extent: f64, step: f64) -> usize {
    if extent.is_nan() || step.is_nan() || extent <= 0.0 || step <= 0.0 {
        return 1;
    }
    (extent / step + 1e-6).floor() as usize + 1
}

/// Whether every voxel axis runs along one world axis.
fn is_axis_aligned(cols: &[DVec3; 3]) -> bool {
    cols.iter()
        .all(|c| (0..3).filter(|&i| !along(c, i)).count() == 2)
}

/// Whether voxel axis `c` has a part along world axis `i` (more than rounding).
fn along(c: &DVec3, i: usize) -> bool {
    c[i].abs() > 1e-6 * c.length()
}

/// The volume's affine with its obliquity removed: each voxel axis along the world axis
/// it runs closest to, with its own spacing and direction, and voxel (0, 0, 0) where it
/// was.
fn acquisition_affine(volume: &Volume) -> (DMat3, DVec3) {
    let o = &volume.orientation;
    let cols = [o.linear.x_axis, o.linear.y_axis, o.linear.z_axis];
    let mut out = [DVec3::ZERO; 3];
    for (j, (world, positive)) in o.axis_map().into_iter().enumerate() {
        let mut c = DVec3::ZERO;
        c[world] = if positive { 1.0 } else { -1.0 } * cols[j].length();
        out[j] = c;
    }
    (DMat3::from_cols(out[0], out[1], out[2]), o.offset)
}

/// Trilinear interpolation at continuous voxel index `t` (edges clamped).
pub(crate) fn trilinear(volume: &Volume, t: DVec3) -> Option<f64> {
    let d = volume.dims;
    let clamp = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64);
    let t = DVec3::new(clamp(t.x, d[0]), clamp(t.y, d[1]), clamp(t.z, d[2]));
    let b = t.floor();
    let f = t - b;
    let i0 = [b.x as usize, b.y as usize, b.z as usize];
    let mut acc = 0.0;
    for corner in 0..8 {
        let mut w = 1.0;
        let mut ijk = [0usize; 3];
        for a in 0..3 {
            let up = corner >> a & 1 != 0;
            ijk[a] = (i0[a] + usize::from(up)).min(d[a] - 1);
            w *= if up { f[a] } else { 1.0 - f[a] };
        }
        if w != 0.0 {
            acc += w * volume.value(ijk[0], ijk[1], ijk[2])?;
        }
    }
    Some(acc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::orient::{AffineSource, Orientation};
    use crate::volume::voxels::VoxelData;

    /// A 4×3×2 volume whose value is its voxel index.
    fn counting(orientation: Orientation) -> Volume {
        let data: Vec<f32> = (0..24).map(|i| i as f32).collect();
        let mut v = Volume::new([4, 3, 2], [1.0; 3], VoxelData::from(data)).expect("volume");
        v.orientation = orientation;
        v
    }

    #[test]
    fn ras_axial_is_flipped_left_right_and_top_bottom() {
        let v = counting(Orientation::from_spacing([1.0; 3]));
        let g = SliceGeometry::new(&v, Plane::Patient);
        assert_eq!(g.dims, [4, 3, 2]);
        let s = g.cut(
            &v,
            SliceAxis::Axial,
            Convention::Radiological,
            0,
            Sampling::Nearest,
        );
        assert_eq!([s.width, s.height], [4, 3]);
        // Top-left: most anterior (y = 2), most right (x = 3).
        assert_eq!(s.values[0], (3 + 4 * 2) as f32);
        assert_eq!(
            g.edge_letters(SliceAxis::Axial, Convention::Radiological),
            ['R', 'L', 'A', 'P']
        );
        let n = g.cut(
            &v,
            SliceAxis::Axial,
            Convention::Neurological,
            0,
            Sampling::Nearest,
        );
        assert_eq!(n.values[0], (4 * 2) as f32);
        assert_eq!(
            g.edge_letters(SliceAxis::Sagittal, Convention::Radiological),
            ['A', 'P', 'S', 'I']
        );
    }

    #[test]
    fn las_volume_gives_the_same_slices_as_its_ras_copy() {
        let mut o = Orientation::from_spacing([1.0; 3]);
        o.linear.x_axis = DVec3::new(-1.0, 0.0, 0.0);
        o.offset = DVec3::new(3.0, 0.0, 0.0);
        o.source = AffineSource::Sform;
        let las = counting(o);
        let ras = las.to_ras();
        for axis in SliceAxis::ALL {
            let a = SliceGeometry::new(&las, Plane::Patient);
            let b = SliceGeometry::new(&ras, Plane::Patient);
            let i = a.middle(axis);
            let sa = a.cut(&las, axis, Convention::Radiological, i, Sampling::Nearest);
            let sb = b.cut(&ras, axis, Convention::Radiological, i, Sampling::Nearest);
            assert_eq!(sa.values, sb.values, "{axis:?}");
        }
    }

    #[test]
    fn pixels_and_world_points_round_trip() {
        let mut v = counting(Orientation::from_spacing([1.0, 1.0, 2.5]));
        v.spacing = [1.0, 1.0, 2.5];
        let g = SliceGeometry::new(&v, Plane::Patient);
        // Coronal: S at 2.5 mm resampled to 1 mm pixels: 2 slices 2.5 mm apart → 3 rows.
        assert_eq!(g.image_size(SliceAxis::Coronal), [4, 3]);
        for axis in SliceAxis::ALL {
            for conv in [Convention::Radiological, Convention::Neurological] {
                let p = g.pixel_to_world(axis, conv, 1.min(g.count(axis) - 1), [1.0, 2.0]);
                let back = g.world_to_pixel(axis, conv, p);
                assert!((back[0] - 1.0).abs() < 1e-9 && (back[1] - 2.0).abs() < 1e-9);
                assert_eq!(g.index_at(axis, p), 1.min(g.count(axis) - 1));
            }
        }
    }

    #[test]
    fn window_ramp() {
        assert_eq!(grey(-1000.0, 400.0, 40.0), 0);
        assert_eq!(grey(240.0, 400.0, 40.0), 255);
        assert_eq!(grey(40.0, 400.0, 40.0), 128);
        assert_eq!(grey(f64::NAN, 400.0, 40.0), 0);
    }
}
