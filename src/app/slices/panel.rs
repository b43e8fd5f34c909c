//! The "Layout and slices" section of the control panel.

use super::{Convention, Layout, Plane, Sampling, SliceViews};

impl SliceViews {
    /// The "Layout and slices" section of the control panel.
    pub fn panel(&mut self, ui: &mut egui::Ui, has_labels: bool) {
        egui::ComboBox::from_label("Layout")
            .selected_text(self.layout.name())
            .show_ui(ui, |ui| {
                for l in Layout::ALL {
                    if ui.selectable_value(&mut self.layout, l, l.name()).clicked() {
                        self.maximised = None;
                    }
                }
            });
        ui.horizontal(|ui| {
            ui.radio_value(
                &mut self.convention,
                Convention::Radiological,
                "Radiological",
            )
            .on_hover_text("The patient's right on the screen's left (PACS, Slicer)");
            ui.radio_value(
                &mut self.convention,
                Convention::Neurological,
                "Neurological",
            )
            .on_hover_text("The patient's left on the screen's left");
        });
        ui.horizontal(|ui| {
            ui.radio_value(&mut self.sampling, Sampling::Nearest, "Nearest");
            ui.radio_value(&mut self.sampling, Sampling::Linear, "Linear");
        });
        ui.horizontal(|ui| {
            ui.radio_value(&mut self.plane, Plane::Patient, "Patient axes")
                .on_hover_text(
                    "Oblique acquisitions resampled onto the patient's axes (as Slicer)",
                );
            ui.radio_value(&mut self.plane, Plane::Acquisition, "Acquisition plane")
                .on_hover_text("An oblique acquisition in its own planes, not resampled");
        });
        ui.checkbox(
            &mut self.linked_window,
            "Window/level of the transfer function",
        );
        if !self.linked_window {
            ui.horizontal(|ui| {
                ui.add(
                    egui::DragValue::new(&mut self.window.0)
                        .prefix("W ")
                        .range(1e-6..=1e9),
                );
                ui.add(egui::DragValue::new(&mut self.window.1).prefix("L "));
            });
        }
        if has_labels {
            ui.checkbox(&mut self.show_labels, "Segments over the slices");
            if self.show_labels {
                ui.add(egui::Slider::new(&mut self.label_opacity, 0.0..=1.0).text("Opacity"));
                ui.checkbox(&mut self.outline, "Outlines only");
            }
        }
        ui.checkbox(&mut self.show_crosshair, "Crosshair");
        ui.checkbox(&mut self.show_markers, "Orientation marker and scale bars");
        ui.weak(
            "Click or drag in a slice: crosshair · wheel: page · shift-click or double-click \
             the 3-D view: crosshair to the surface · drag inside a shape's outline: move it, \
             on it: resize · right-click a slice: new shape at the crosshair, cut here",
        );
    }
}
