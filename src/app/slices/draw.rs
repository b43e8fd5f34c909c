//! What the slice panes draw that depends on nothing of their state: the planes'
//! colours, the clip shapes' outlines in a slice, the scale bar and the 3-D pane's
//! orientation marker.

use crate::clip::ClipShape;
use crate::slice::{Convention, SliceAxis, SliceGeometry, world_to_volume};
use egui::{Color32, Pos2, Rect, Stroke, Vec2, pos2};
use glam::Vec3;

/// The colour of each plane (its crosshair line and its pane's name), as Slicer's
/// red, green and yellow views.
pub(super) fn plane_color(axis: SliceAxis) -> Color32 {
    match axis {
        SliceAxis::Axial => Color32::from_rgb(240, 80, 70),
        SliceAxis::Coronal => Color32::from_rgb(100, 200, 90),
        SliceAxis::Sagittal => Color32::from_rgb(235, 200, 60),
    }
}

/// The outlines of the shapes in a slice, as segments between pixel corners (pixel
/// coordinates), traced on a grid of at most ~200 cells per side.
pub(super) fn cross_sections(
    geometry: &SliceGeometry,
    volume: &crate::volume::Volume,
    axis: SliceAxis,
    conv: Convention,
    index: usize,
    shapes: &[ClipShape],
) -> Vec<[Pos2; 2]> {
    let [w, h] = geometry.image_size(axis);
    let step = (w.max(h) / 200).max(1);
    let (cols, rows) = (w.div_ceil(step) + 1, h.div_ceil(step) + 1);
    let mut out = Vec::new();
    for s in shapes {
        if s.contains(Vec3::ZERO).is_none() {
            continue;
        }
        // Inside-ness at the grid's corners (pixel coordinates − ½: pixel edges). Pixel
        // to world to the shape's frame is affine: three points give every corner.
        let local = |c: usize, r: usize| {
            let pixel = [(c * step) as f64 - 0.5, (r * step) as f64 - 0.5];
            let world = geometry.pixel_to_world(axis, conv, index, pixel);
            s.to_local(world_to_volume(volume, world))
        };
        let origin = local(0, 0);
        let (across, down) = (local(1, 0) - origin, local(0, 1) - origin);
        let inside: Vec<bool> = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (c, r)))
            .map(|(c, r)| {
                let at = origin + across * c as f32 + down * r as f32;
                s.contains_local(at).unwrap_or(false)
            })
            .collect();
        let at = |c: usize, r: usize| inside[r * cols + c];
        let p = |c: f64, r: f64| {
            pos2(
                (c * step as f64 - 0.5) as f32,
                (r * step as f64 - 0.5) as f32,
            )
        };
        // Marching squares, one segment per cell between the midpoints of its changing edges.
        for r in 0..rows - 1 {
            for c in 0..cols - 1 {
                let v = [at(c, r), at(c + 1, r), at(c + 1, r + 1), at(c, r + 1)];
                let mids = [
                    (v[0] != v[1]).then(|| p(c as f64 + 0.5, r as f64)),
                    (v[1] != v[2]).then(|| p(c as f64 + 1.0, r as f64 + 0.5)),
                    (v[2] != v[3]).then(|| p(c as f64 + 0.5, r as f64 + 1.0)),
                    (v[3] != v[0]).then(|| p(c as f64, r as f64 + 0.5)),
                ];
                let m: Vec<Pos2> = mids.into_iter().flatten().collect();
                match m.as_slice() {
                    [a, b] => out.push([*a, *b]),
                    [a, b, c2, d] => {
                        out.push([*a, *b]);
                        out.push([*c2, *d]);
                    }
                    _ => {}
                }
            }
        }
    }
    out
}

/// A scale bar in the bottom-right corner of `rect` for `mm_per_point`.
pub(super) fn scale_bar(painter: &egui::Painter, rect: Rect, mm_per_point: f32) {
    let Some((mm, label)) =
        crate::slice::scale_bar_length(f64::from(mm_per_point), f64::from(rect.width()))
    else {
        return;
    };
    let len = mm as f32 / mm_per_point;
    let right = rect.right() - 28.0;
    let y = rect.bottom() - 26.0;
    let stroke = Stroke::new(2.0, Color32::from_gray(230));
    painter.line_segment([pos2(right - len, y), pos2(right, y)], stroke);
    for x in [right - len, right] {
        painter.line_segment([pos2(x, y - 4.0), pos2(x, y)], stroke);
    }
    painter.text(
        pos2(right - len / 2.0, y - 5.0),
        egui::Align2::CENTER_BOTTOM,
        label,
        egui::FontId::proportional(12.0),
        Color32::from_gray(230),
    );
}

/// Labelled axes R, A, S as the camera sees them, in the bottom-left corner.
pub(super) fn orientation_marker(
    painter: &egui::Painter,
    rect: Rect,
    camera: &crate::render::Camera,
) {
    let (right, up) = camera.screen_axes();
    let back = camera.backward();
    let origin = pos2(rect.left() + 40.0, rect.bottom() - 40.0);
    let len = 24.0;
    let mut axes: Vec<(Vec3, char, Color32)> = vec![
        (Vec3::X, 'R', Color32::from_rgb(230, 90, 80)),
        (Vec3::Y, 'A', Color32::from_rgb(110, 210, 100)),
        (Vec3::Z, 'S', Color32::from_rgb(100, 150, 255)),
    ];
    // Far axes first, so near ones draw over them.
    axes.sort_by(|a, b| a.0.dot(back).total_cmp(&b.0.dot(back)));
    for (d, letter, color) in axes {
        let end = origin + Vec2::new(d.dot(right), -d.dot(up)) * len;
        painter.line_segment([origin, end], Stroke::new(2.0, color));
        painter.text(
            origin + (end - origin) * 1.35,
            egui::Align2::CENTER_CENTER,
            letter,
            egui::FontId::proportional(12.0),
            color,
        );
    }
}
