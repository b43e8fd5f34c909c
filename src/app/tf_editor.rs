//! The transfer-function editor: the volume's histogram (log scale) with the
//! piecewise-linear opacity curve on top, a colour bar with its stops below, presets and
//! window/level.
//!
//! Mouse: drag a point to move it, double-click to add one, right-click a point to remove
//! it; the same on the colour bar (click a stop to pick its colour). Dragging with the
//! right or middle button on the curve changes window (horizontal) and level
//! (vertical). Edits keep both lists sorted, so the function always validates.

use crate::ao::filter::{OpacityModulation, StatisticSource};
use crate::tf::{ColorStop, OpacityPoint, Preset, TransferFunction};
use crate::volume::{Histogram, Stats};
use egui::{Color32, Pos2, Rect, Sense, Stroke, Vec2, pos2, vec2};

/// Pick radius around a control point, in points.
const PICK: f32 = 7.0;

/// Editor state that lives between frames (what is being dragged).
#[derive(Debug, Default)]
pub struct TfEditor {
    drag: Option<Drag>,
    /// The colour stop whose colour the picker edits.
    pub selected_stop: Option<usize>,
    /// The value range on screen, frozen while dragging so the axis does not move.
    frozen_range: Option<(f64, f64)>,
}

#[derive(Debug)]
enum Drag {
    Opacity(usize),
    Color(usize),
    WindowLevel {
        start: TransferFunction,
        window: f64,
        level: f64,
    },
}

/// Opacity modulation by local variance (Ruiz et al. §4.2), the transfer function's
/// companion: a checkbox, then `σ²_max`, the box radius and what the variance is of.
/// `status` (computing, an error) is shown under them. Returns whether `m` changed.
pub fn modulation_controls(
    ui: &mut egui::Ui,
    m: &mut Option<OpacityModulation>,
    status: &str,
) -> bool {
    let before = *m;
    let mut on = m.is_some();
    ui.checkbox(&mut on, "Opacity modulation by local variance")
        .on_hover_text(
            "α · min(σ²/σ²_max, 1) (Ruiz et al. §4.2): homogeneous regions fade, boundaries stay",
        );
    match (on, m.is_some()) {
        (true, false) => *m = Some(OpacityModulation::default()),
        (false, true) => *m = None,
        _ => {}
    }
    if let Some(m) = m {
        ui.add(
            super::ao_panel::slider(&mut m.sigma2_max, 1e-6..=1.0)
                .logarithmic(true)
                .text("σ²_max"),
        );
        ui.add(
            super::ao_panel::slider(&mut m.radius, 1.0..=20.0)
                .step_by(1.0)
                .text("Box radius (voxels)"),
        );
        ui.horizontal(|ui| {
            ui.label("Variance of");
            ui.selectable_value(&mut m.source, StatisticSource::Density, "density");
            ui.selectable_value(&mut m.source, StatisticSource::Opacity, "opacity");
        });
        if !status.is_empty() {
            ui.weak(status);
        }
    }
    *m != before
}

/// Inserts `item` after every element whose key is ≤ its key; returns its index.
fn insert_sorted<T>(list: &mut Vec<T>, item: T, key: impl Fn(&T) -> f64) -> usize {
    let k = key(&item);
    let i = list.partition_point(|p| key(p) <= k);
    list.insert(i, item);
    i
}

/// `value` clamped between the neighbours of element `i`, so the list stays sorted.
fn between_neighbours<T>(list: &[T], i: usize, value: f64, key: impl Fn(&T) -> f64) -> f64 {
    let lo = if i > 0 {
        key(&list[i - 1])
    } else {
        f64::NEG_INFINITY
    };
    let hi = list.get(i + 1).map_or(f64::INFINITY, key);
    value.clamp(lo, hi)
}

/// Adds an opacity point, keeping the list sorted. Returns its index.
pub fn add_opacity(tf: &mut TransferFunction, value: f64, alpha: f32) -> usize {
    let p = OpacityPoint {
        value,
        alpha: alpha.clamp(0.0, 1.0),
    };
    insert_sorted(&mut tf.opacity, p, |p| p.value)
}

/// Moves opacity point `i`; the value stays between its neighbours, alpha in [0, 1].
pub fn move_opacity(tf: &mut TransferFunction, i: usize, value: f64, alpha: f32) {
    if i < tf.opacity.len() {
        let value = between_neighbours(&tf.opacity, i, value, |p| p.value);
        tf.opacity[i] = OpacityPoint {
            value,
            alpha: alpha.clamp(0.0, 1.0),
        };
    }
}

/// Removes opacity point `i` unless it is the last one (a function needs a point).
pub fn remove_opacity(tf: &mut TransferFunction, i: usize) -> bool {
    let ok = tf.opacity.len() > 1 && i < tf.opacity.len();
    if ok {
        tf.opacity.remove(i);
    }
    ok
}

/// Adds a colour stop with the colour the function has there now. Returns its index.
pub fn add_color(tf: &mut TransferFunction, value: f64) -> usize {
    let c = tf.eval(value);
    let stop = ColorStop {
        value,
        rgb: [c[0], c[1], c[2]],
    };
    insert_sorted(&mut tf.color, stop, |c| c.value)
}

/// Moves colour stop `i`, keeping it between its neighbours.
pub fn move_color(tf: &mut TransferFunction, i: usize, value: f64) {
    if i < tf.color.len() {
        tf.color[i].value = between_neighbours(&tf.color, i, value, |c| c.value);
    }
}

/// Removes colour stop `i` unless it is the last one.
pub fn remove_color(tf: &mut TransferFunction, i: usize) -> bool {
    let ok = tf.color.len() > 1 && i < tf.color.len();
    if ok {
        tf.color.remove(i);
    }
    ok
}

/// The value range the editor shows: the data's range, widened to hold every point.
pub fn plot_range(stats: &Stats, tf: &TransferFunction) -> (f64, f64) {
    let (mut lo, mut hi) = if stats.max > stats.min {
        (stats.min, stats.max)
    } else {
        (stats.min - 0.5, stats.min + 0.5)
    };
    for v in tf
        .opacity
        .iter()
        .map(|p| p.value)
        .chain(tf.color.iter().map(|c| c.value))
        .filter(|v| v.is_finite())
    {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi)
}

/// Maps between data values / alpha and screen positions inside `rect`.
#[derive(Debug, Clone, Copy)]
struct Axes {
    rect: Rect,
    lo: f64,
    hi: f64,
}

impl Axes {
    fn x(&self, value: f64) -> f32 {
        let t = ((value - self.lo) / (self.hi - self.lo)) as f32;
        self.rect.left() + t * self.rect.width()
    }
    fn value(&self, x: f32) -> f64 {
        self.lo + ((x - self.rect.left()) / self.rect.width()) as f64 * (self.hi - self.lo)
    }
    fn y(&self, alpha: f32) -> f32 {
        self.rect.bottom() - alpha * self.rect.height()
    }
    fn alpha(&self, y: f32) -> f32 {
        ((self.rect.bottom() - y) / self.rect.height()).clamp(0.0, 1.0)
    }
    fn point(&self, p: &OpacityPoint) -> Pos2 {
        pos2(self.x(p.value), self.y(p.alpha))
    }
}

/// Index of the item whose screen position is nearest `pos`, within [`PICK`].
fn nearest(positions: impl Iterator<Item = Pos2>, pos: Pos2) -> Option<usize> {
    positions
        .enumerate()
        .map(|(i, p)| (i, p.distance(pos)))
        .filter(|(_, d)| *d <= PICK)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The colour the renderer shows for TF rgb (values go to the screen as they are).
fn color32(rgb: [f32; 3], alpha: f32) -> Color32 {
    let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    Color32::from_rgba_unmultiplied(c(rgb[0]), c(rgb[1]), c(rgb[2]), c(alpha))
}

impl TfEditor {
    /// Shows the editor; returns whether `tf` changed.
    pub fn show(
        &mut self,
        ui: &mut egui::Ui,
        tf: &mut TransferFunction,
        histogram: &Histogram,
        stats: &Stats,
    ) -> bool {
        let before = tf.clone();
        ui.horizontal(|ui| {
            egui::ComboBox::from_label("Preset")
                .selected_text(tf.name.clone())
                .show_ui(ui, |ui| {
                    for p in Preset::ALL {
                        if ui.selectable_label(tf.name == p.name(), p.name()).clicked() {
                            *tf = TransferFunction::preset(p, stats);
                            self.selected_stop = None;
                        }
                    }
                });
        });
        let (lo, hi) = self.frozen_range.unwrap_or_else(|| plot_range(stats, tf));
        let width = ui.available_width().max(120.0);
        let (rect, curve) = ui.allocate_exact_size(vec2(width, 130.0), Sense::click_and_drag());
        curve.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, true, "Opacity curve"));
        let axes = Axes { rect, lo, hi };
        self.curve_input(ui, &curve, tf, axes);
        paint_curve(ui, tf, histogram, axes);
        let (bar_rect, bar) = ui.allocate_exact_size(vec2(width, 18.0), Sense::click_and_drag());
        bar.widget_info(|| egui::WidgetInfo::labeled(egui::Role::Canvas, true, "Colour bar"));
        let bar_axes = Axes {
            rect: bar_rect,
            lo,
            hi,
        };
        self.bar_input(&bar, tf, bar_axes);
        self.paint_bar(ui, tf, bar_axes);
        if self.drag.is_none() {
            self.frozen_range = None;
        }

        if let Some(i) = self.selected_stop.filter(|&i| i < tf.color.len()) {
            ui.horizontal(|ui| {
                ui.label(format!("Stop at {:.1}", tf.color[i].value));
                let c = color32(tf.color[i].rgb, 1.0);
                let mut rgb = [c.r(), c.g(), c.b()];
                if egui::color_picker::color_edit_button_srgb(ui, &mut rgb).changed() {
                    tf.color[i].rgb = rgb.map(|x| x as f32 / 255.0);
                }
            });
        }
        let (window, level) = tf.window_level();
        let (mut w, mut l) = (window, level);
        ui.horizontal(|ui| {
            let speed = ((hi - lo) / 500.0).max(1e-6);
            ui.label("Window");
            ui.add(
                egui::DragValue::new(&mut w)
                    .speed(speed)
                    .range(0.0..=f64::MAX),
            )
            .accessible_name("Window");
            ui.label("Level");
            ui.add(egui::DragValue::new(&mut l).speed(speed))
                .accessible_name("Level");
        });
        if (w, l) != (window, level) {
            *tf = tf.with_window_level(w, l);
        }
        ui.weak("Drag points · double-click adds · right-click removes · right-drag: window/level");
        *tf != before
    }

    fn curve_input(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        tf: &mut TransferFunction,
        axes: Axes,
    ) {
        let pointer = response.interact_pointer_pos().or(response.hover_pos());
        let hit = pointer.and_then(|p| nearest(tf.opacity.iter().map(|q| axes.point(q)), p));
        if response.drag_started_by(egui::PointerButton::Primary) {
            let origin = ui.input(|i| i.pointer.press_origin()).or(pointer);
            let start = origin.and_then(|p| nearest(tf.opacity.iter().map(|q| axes.point(q)), p));
            self.drag = start.map(Drag::Opacity);
            self.frozen_range = Some((axes.lo, axes.hi));
        } else if response.drag_started_by(egui::PointerButton::Secondary)
            || response.drag_started_by(egui::PointerButton::Middle)
        {
            let (window, level) = tf.window_level();
            self.drag = Some(Drag::WindowLevel {
                start: tf.clone(),
                window,
                level,
            });
            self.frozen_range = Some((axes.lo, axes.hi));
        }
        match &self.drag {
            Some(Drag::Opacity(i)) if response.dragged() => {
                if let Some(p) = pointer {
                    move_opacity(tf, *i, axes.value(p.x), axes.alpha(p.y));
                }
            }
            Some(Drag::WindowLevel {
                start,
                window,
                level,
            }) if response.dragged() => {
                let total: Vec2 = ui.input(|i| {
                    i.pointer
                        .press_origin()
                        .zip(i.pointer.latest_pos())
                        .map_or(Vec2::ZERO, |(a, b)| b - a)
                });
                let per_point = (axes.hi - axes.lo) / axes.rect.width() as f64;
                let w = (window + total.x as f64 * per_point).max(per_point);
                let l = level - total.y as f64 * per_point;
                *tf = start.with_window_level(w, l);
            }
            _ => {}
        }
        if response.drag_stopped() {
            self.drag = None;
        }
        if response.double_clicked()
            && hit.is_none()
            && let Some(p) = pointer
        {
            add_opacity(tf, axes.value(p.x), axes.alpha(p.y));
        }
        if response.secondary_clicked()
            && let Some(i) = hit
        {
            remove_opacity(tf, i);
        }
    }

    fn bar_input(&mut self, response: &egui::Response, tf: &mut TransferFunction, axes: Axes) {
        let pointer = response.interact_pointer_pos().or(response.hover_pos());
        let y = axes.rect.center().y;
        let hit = pointer.and_then(|p| {
            nearest(
                tf.color.iter().map(|c| pos2(axes.x(c.value), y)),
                pos2(p.x, y),
            )
        });
        if response.drag_started_by(egui::PointerButton::Primary) {
            self.drag = hit.map(Drag::Color);
            self.selected_stop = hit.or(self.selected_stop);
            self.frozen_range = Some((axes.lo, axes.hi));
        }
        if let (Some(Drag::Color(i)), true, Some(p)) = (&self.drag, response.dragged(), pointer) {
            move_color(tf, *i, axes.value(p.x));
        }
        if response.drag_stopped() {
            self.drag = None;
        }
        if response.clicked() {
            self.selected_stop = hit;
        }
        if response.double_clicked()
            && hit.is_none()
            && let Some(p) = pointer
        {
            self.selected_stop = Some(add_color(tf, axes.value(p.x)));
        }
        if response.secondary_clicked()
            && let Some(i) = hit
            && remove_color(tf, i)
        {
            self.selected_stop = None;
        }
    }

    fn paint_bar(&self, ui: &egui::Ui, tf: &TransferFunction, axes: Axes) {
        let painter = ui.painter_at(axes.rect.expand(4.0));
        let rect = axes.rect;
        let steps = (rect.width() / 2.0).max(1.0) as usize;
        for s in 0..steps {
            let x0 = rect.left() + s as f32 * 2.0;
            let c = tf.eval(axes.value(x0 + 1.0));
            painter.rect_filled(
                Rect::from_min_max(pos2(x0, rect.top()), pos2(x0 + 2.0, rect.bottom())),
                0.0,
                color32([c[0], c[1], c[2]], 1.0),
            );
        }
        for (i, c) in tf.color.iter().enumerate() {
            let x = axes.x(c.value);
            let selected = self.selected_stop == Some(i);
            painter.circle(
                pos2(x, rect.center().y),
                if selected { 6.0 } else { 4.5 },
                color32(c.rgb, 1.0),
                Stroke::new(
                    if selected { 2.0 } else { 1.0 },
                    ui.visuals().strong_text_color(),
                ),
            );
        }
    }
}

fn paint_curve(ui: &egui::Ui, tf: &TransferFunction, histogram: &Histogram, axes: Axes) {
    let rect = axes.rect;
    let painter = ui.painter_at(rect.expand(4.0));
    painter.rect_filled(rect, 2.0, ui.visuals().extreme_bg_color);
    // Histogram, log scale: the background peak of CT/MR would flatten everything else.
    let peak = histogram.counts.iter().copied().max().unwrap_or(0);
    let scale = ((peak + 1) as f64).ln().max(1e-9);
    let bins = histogram.counts.len();
    let bin_width = (histogram.max - histogram.min) / bins.max(1) as f64;
    let bar = ui.visuals().weak_text_color().gamma_multiply(0.5);
    for (i, &n) in histogram.counts.iter().enumerate() {
        if n == 0 {
            continue;
        }
        let h = (((n + 1) as f64).ln() / scale) as f32 * rect.height();
        let x0 = axes.x(histogram.bin_start(i));
        let x1 = axes.x(histogram.bin_start(i) + bin_width).max(x0 + 1.0);
        painter.rect_filled(
            Rect::from_min_max(pos2(x0, rect.bottom() - h), pos2(x1, rect.bottom())),
            0.0,
            bar,
        );
    }
    // The function's colour under its opacity, then the curve and its points.
    let steps = (rect.width() / 2.0).max(1.0) as usize;
    for s in 0..steps {
        let x0 = rect.left() + s as f32 * 2.0;
        let c = tf.eval(axes.value(x0 + 1.0));
        if c[3] > 0.0 {
            painter.rect_filled(
                Rect::from_min_max(pos2(x0, axes.y(c[3])), pos2(x0 + 2.0, rect.bottom())),
                0.0,
                color32([c[0], c[1], c[2]], 0.45),
            );
        }
    }
    let mut line: Vec<Pos2> = Vec::with_capacity(tf.opacity.len() + 2);
    if let Some(first) = tf.opacity.first() {
        line.push(pos2(rect.left(), axes.y(first.alpha)));
    }
    line.extend(tf.opacity.iter().map(|p| axes.point(p)));
    if let Some(last) = tf.opacity.last() {
        line.push(pos2(rect.right(), axes.y(last.alpha)));
    }
    let stroke = Stroke::new(1.5, ui.visuals().strong_text_color());
    painter.add(egui::Shape::line(line, stroke));
    for p in &tf.opacity {
        painter.circle(axes.point(p), 4.0, ui.visuals().selection.bg_fill, stroke);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tf() -> TransferFunction {
        TransferFunction {
            name: "t".into(),
            opacity: OpacityPoint::list(&[(0.0, 0.0), (100.0, 1.0)]),
            color: ColorStop::list(&[(0.0, [0.0; 3]), (100.0, [1.0, 0.5, 0.0])]),
        }
    }

    #[test]
    fn edits_keep_the_function_valid() {
        let mut t = tf();
        let i = add_opacity(&mut t, 50.0, 2.0);
        assert_eq!(i, 1);
        assert_eq!(t.opacity[1].alpha, 1.0, "alpha clamped");
        // A point cannot be dragged past its neighbours.
        move_opacity(&mut t, 1, 500.0, 0.25);
        assert_eq!(t.opacity[1].value, 100.0);
        assert_eq!(t.opacity[1].alpha, 0.25);
        move_opacity(&mut t, 1, -500.0, 0.25);
        assert_eq!(t.opacity[1].value, 0.0);
        t.validate().expect("still valid");
        assert!(remove_opacity(&mut t, 1));
        assert!(remove_opacity(&mut t, 0));
        assert!(!remove_opacity(&mut t, 0), "the last point stays");
        assert_eq!(t.opacity.len(), 1);

        let mut t = tf();
        let i = add_color(&mut t, 50.0);
        assert_eq!(i, 1);
        assert_eq!(
            t.color[1].rgb,
            [0.5, 0.25, 0.0],
            "colour of the function there"
        );
        move_color(&mut t, 1, 1e9);
        assert_eq!(t.color[1].value, 100.0);
        t.validate().expect("still valid");
        assert!(remove_color(&mut t, 0) && remove_color(&mut t, 0));
        assert!(!remove_color(&mut t, 0));
    }

    #[test]
    fn the_plot_range_holds_data_and_points() {
        let stats = Stats {
            min: 10.0,
            max: 50.0,
            mean: 20.0,
            non_finite: 0,
            finite: 8,
        };
        assert_eq!(plot_range(&stats, &tf()), (0.0, 100.0));
        let constant = Stats { max: 10.0, ..stats };
        let mut t = tf();
        t.opacity.truncate(1);
        t.opacity[0].value = 10.0;
        t.color.truncate(1);
        t.color[0].value = 10.0;
        assert_eq!(plot_range(&constant, &t), (9.5, 10.5));
    }

    #[test]
    fn axes_round_trip() {
        let axes = Axes {
            rect: Rect::from_min_size(pos2(10.0, 20.0), vec2(200.0, 100.0)),
            lo: -1000.0,
            hi: 3000.0,
        };
        for v in [-1000.0, 0.0, 1234.5, 3000.0] {
            assert!((axes.value(axes.x(v)) - v).abs() < 0.05);
        }
        assert_eq!(axes.alpha(axes.y(0.25)), 0.25);
        assert_eq!(axes.alpha(0.0), 1.0, "clamped above the plot");
    }
}
