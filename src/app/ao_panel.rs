//! The ambient-occlusion panel: method, parameters, the "AO only" view and live
//! statistics.
//!
//! Methods are listed from [`AoMethod::ALL`] by their names for people, grouped by what
//! they are for ([`AoGroup`]), each with its one-line summary and a tooltip; the codes
//! scene files and the CLI use (`cao`, `lao`, …) appear in the tooltips.

use crate::ao::cone::{ConePreset, ConeSet};
use crate::ao::filter::{RadiusUnit, StatisticSource};
use crate::ao::rays::RaySet;
use crate::ao::settings::AoGroup;
use crate::ao::vao::VaoSettings;
use crate::ao::{AoMethod, AoSettings};

/// Every AO method this build knows, with its code (as scene files write it), in the
/// order the panel lists them.
pub fn methods() -> Vec<(String, AoMethod)> {
    AoMethod::ALL
        .into_iter()
        .map(|m| (m.code().to_owned(), m))
        .collect()
}

/// The method's code as scene files and the CLI write it ("lao").
pub fn method_name(m: AoMethod) -> String {
    m.code().to_owned()
}

/// What the statistics block shows.
#[derive(Debug, Clone, Default)]
pub struct AoStats {
    /// Mean time between viewport frames while the view changes (ms).
    pub frame_ms: Option<f32>,
    /// Ray-cast frames drawn so far.
    pub frames: u64,
    /// The last AO computation: seconds and what ran it.
    pub ao_seconds: Option<f64>,
    pub ao_device: Option<String>,
    /// Voxels whose AO the last frame recomputed, in percent (precomputed methods: 0).
    pub recomputed_percent: Option<f64>,
    /// CAO's per-frame stage times.
    pub stages: Option<String>,
    /// "computing…", "ready", an error.
    pub status: String,
}

const RAY_SETS: [RaySet; 4] = [
    RaySet::Six,
    RaySet::Fourteen,
    RaySet::TwentySix,
    RaySet::FiftyFour,
];

/// Shows the panel. Returns `(settings changed, view changed)`: the first means the AO
/// volume must be recomputed, the second only that the frame looks different.
pub fn show(
    ui: &mut egui::Ui,
    settings: &mut AoSettings,
    ambient: &mut f32,
    strength: &mut f32,
    offset: &mut f32,
    ao_only: &mut bool,
    stats: &AoStats,
) -> (bool, bool) {
    let before = *settings;
    let view_before = (*ambient, *strength, *offset, *ao_only);
    method_combo(ui, &mut settings.method);
    ui.weak(settings.method.summary());
    ui.add_enabled_ui(settings.method != AoMethod::None, |ui| {
        if crate::ao::fast::map_of(settings.method).is_some() {
            filter_parameters(ui, settings);
        } else if settings.method == AoMethod::Cone {
            cone_parameters(ui, settings);
        } else if matches!(settings.method, AoMethod::Vao | AoMethod::VaoLive) {
            vao_parameters(ui, &mut settings.vao);
        } else {
            ray_parameters(ui, settings);
        }
    });
    ui.add(egui::Slider::new(strength, 0.0..=3.0).text("AO strength s"))
        .on_hover_text("How deep occlusion darkens: 0 no AO, 1 as computed, above 1 deeper");
    let reach = crate::sample::AO_READ_REACH as f32;
    ui.add(egui::Slider::new(offset, 0.0..=reach).text("AO read offset (voxels)"))
        .on_hover_text(
            "Where a sample reads the AO: this far out of the material along the normal, \
             where the occlusion a surface sees is (0: at the sample, which greys surfaces)",
        );
    ui.add(egui::Slider::new(ambient, 0.0..=1.0).text("Ambient share k"))
        .on_hover_text("The share of ambient light; the rest is diffuse (both scaled by the AO)");
    ui.checkbox(ao_only, "AO only (white, ambient term alone)");
    egui::CollapsingHeader::new("Statistics").show(ui, |ui| statistics(ui, stats));
    (
        *settings != before,
        (*ambient, *strength, *offset, *ao_only) != view_before,
    )
}

/// The method list: each group's heading, then its methods by name with their summary
/// beside them and the details (and the CLI's code) in a tooltip.
fn method_combo(ui: &mut egui::Ui, method: &mut AoMethod) {
    egui::ComboBox::from_label("Method")
        .selected_text(method.label())
        .width(190.0)
        // Tall enough for every entry without a scroll bar.
        .height(600.0)
        .show_ui(ui, |ui| {
            for group in AoGroup::ALL {
                let members: Vec<AoMethod> = AoMethod::ALL
                    .into_iter()
                    .filter(|m| m.group() == group)
                    .collect();
                if group != AoGroup::Off {
                    ui.separator();
                    ui.strong(group.title());
                }
                for m in members {
                    ui.selectable_value(method, m, m.label())
                        .on_hover_text(tooltip(m));
                }
            }
        })
        .response
        .on_hover_text(tooltip(*method));
}

/// A method's tooltip: its summary, how it works and its code for scene files and the CLI.
pub fn tooltip(m: AoMethod) -> String {
    format!(
        "{}.\n\n{}\n\nScene files and the CLI: --ao {}",
        m.summary(),
        m.details(),
        m.code()
    )
}

/// A slider over the usual range that leaves a value outside it (from a scene file)
/// intact until the user moves it; egui's default clamps even values it only shows.
pub fn slider<N: egui::emath::Numeric>(
    value: &mut N,
    range: std::ops::RangeInclusive<N>,
) -> egui::Slider<'_> {
    egui::Slider::new(value, range).clamping(egui::SliderClamping::Edits)
}

/// LAO and CAO: K rays of M samples.
fn ray_parameters(ui: &mut egui::Ui, settings: &mut AoSettings) {
    ui.horizontal(|ui| {
        egui::ComboBox::from_label("Rays K")
            .selected_text(settings.rays.name())
            .show_ui(ui, |ui| {
                for r in RAY_SETS {
                    ui.selectable_value(&mut settings.rays, r, r.name());
                }
                if ui
                    .selectable_label(matches!(settings.rays, RaySet::Fibonacci(_)), "Fibonacci")
                    .clicked()
                {
                    settings.rays = RaySet::Fibonacci(128);
                }
            });
        if let RaySet::Fibonacci(n) = &mut settings.rays {
            ui.label("N");
            ui.add(egui::DragValue::new(n).range(1..=65536))
                .accessible_name("N");
        }
    });
    ui.add(slider(&mut settings.samples, 1..=64).text("Samples M"));
    ui.weak(format!(
        "Radius R = {} mm (samples 1 mm apart)",
        settings.samples
    ));
}

/// The filter maps (Ruiz et al.): the box radius and what the statistics are of.
fn filter_parameters(ui: &mut egui::Ui, settings: &mut AoSettings) {
    ui.horizontal(|ui| {
        ui.add(
            slider(&mut settings.radius, 1.0..=30.0)
                .step_by(1.0)
                .text("Box radius r"),
        );
        ui.selectable_value(&mut settings.radius_unit, RadiusUnit::Voxels, "voxels");
        ui.selectable_value(&mut settings.radius_unit, RadiusUnit::Mm, "mm");
    });
    ui.horizontal(|ui| {
        ui.label("Statistics of");
        ui.selectable_value(&mut settings.statistic, StatisticSource::Density, "density");
        ui.selectable_value(&mut settings.statistic, StatisticSource::Opacity, "opacity");
    });
    ui.weak("Box of side 2r + 1 around each voxel");
}

/// Cone tracing: cones over the sphere, spheres per cone and their reach.
fn cone_parameters(ui: &mut egui::Ui, settings: &mut AoSettings) {
    ui.horizontal(|ui| {
        ui.label("Cones");
        for c in [ConeSet::Six, ConeSet::Fourteen, ConeSet::TwentySix] {
            ui.selectable_value(&mut settings.cones, c, c.count().to_string());
        }
    });
    ui.horizontal(|ui| {
        ui.label("Spheres per cone");
        for p in [ConePreset::Low, ConePreset::Medium, ConePreset::High] {
            let label = format!("{} ({})", p.name(), p.spheres());
            ui.selectable_value(&mut settings.cone_preset, p, label);
        }
    });
    ui.add(slider(&mut settings.samples, 1..=64).text("Reach (mm)"));
}

/// Positional AO (Papaioannou et al.): rays, samples, reach and the opacity that stops
/// a ray; the isosurface variant's value and tolerance when the scene uses it.
fn vao_parameters(ui: &mut egui::Ui, vao: &mut VaoSettings) {
    ui.add(slider(&mut vao.directions, 1..=256).text("Rays N_dir"));
    ui.add(slider(&mut vao.samples, 1..=64).text("Samples per ray"));
    ui.add(slider(&mut vao.r_max_mm, 1.0..=100.0).text("Reach r_max (mm)"));
    ui.add(slider(&mut vao.v_thres, 0.01..=1.0).text("Stop at opacity V_thres"));
    if let Some(i) = &mut vao.isosurface {
        ui.horizontal(|ui| {
            ui.label("Isosurface");
            ui.add(egui::DragValue::new(&mut i.value))
                .accessible_name("Isovalue");
            ui.label("± tolerance");
            ui.add(egui::DragValue::new(&mut i.tolerance).range(0.0..=f64::MAX))
                .accessible_name("Isovalue tolerance");
        });
    }
    // The isosurface variant comes from the scene or `--vao-iso`; it can be left here.
    if vao.isosurface.is_some() && ui.button("Beer's law instead of the isosurface").clicked() {
        vao.isosurface = None;
    }
}

/// Frame time, AO time and share of voxels recomputed (collapsed by default: the numbers
/// change every frame).
fn statistics(ui: &mut egui::Ui, stats: &AoStats) {
    egui::Grid::new("ao_stats").num_columns(2).show(ui, |ui| {
        ui.label("AO");
        ui.label(&stats.status);
        ui.end_row();
        ui.label("Frame time");
        ui.label(stats.frame_ms.map_or("—".into(), |ms| {
            format!("{ms:.0} ms ({:.1} fps)", 1e3 / ms.max(1e-3))
        }));
        ui.end_row();
        ui.label("Frames drawn");
        ui.label(stats.frames.to_string());
        ui.end_row();
        ui.label("AO precomputation");
        ui.label(match (&stats.ao_seconds, &stats.ao_device) {
            (Some(s), Some(d)) => format!("{:.0} ms on {d}", s * 1e3),
            (Some(s), None) => format!("{:.0} ms", s * 1e3),
            _ => "—".into(),
        });
        ui.end_row();
        ui.label("CAO stages");
        ui.label(stats.stages.clone().unwrap_or_else(|| "—".into()));
        ui.end_row();
        ui.label("Voxels recomputed per frame");
        ui.label(
            stats
                .recomputed_percent
                .map_or("—".into(), |p| format!("{p:.2} %")),
        );
        ui.end_row();
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_is_listed_once_with_its_code_name_and_group() {
        let m = methods();
        assert_eq!(m.len(), AoMethod::ALL.len());
        for (code, method) in &m {
            assert_eq!(AoMethod::parse(code), Ok(*method), "{code}");
            assert_eq!(m.iter().filter(|(_, k)| k == method).count(), 1);
            // Scene files write the same code.
            assert_eq!(
                serde_json::to_value(method).ok(),
                Some(code.as_str().into())
            );
            assert!(tooltip(*method).contains(code.as_str()));
        }
        let labels: std::collections::HashSet<_> = m.iter().map(|(_, k)| k.label()).collect();
        assert_eq!(labels.len(), m.len(), "two methods share a label");
        // The list is grouped: a group's members are consecutive.
        let groups: Vec<AoGroup> = AoMethod::ALL.iter().map(|k| k.group()).collect();
        let mut seen: Vec<AoGroup> = Vec::new();
        for g in groups {
            if seen.last() != Some(&g) {
                assert!(!seen.contains(&g), "{g:?} is split");
                seen.push(g);
            }
        }
        assert_eq!(AoMethod::Cao.group(), AoGroup::FollowsCuts);
        assert_eq!(AoMethod::Lao.group(), AoGroup::Precomputed);
    }
}
