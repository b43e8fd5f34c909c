//! The ambient-occlusion panel: method, parameters, the "AO only" view and live
//! statistics.
//!
//! Methods are listed from [`AoMethod`] itself (the names its parser accepts, written as
//! scene files write them), so methods appear here as they land in `ao`.

use crate::ao::cone::{ConePreset, ConeSet};
use crate::ao::filter::{RadiusUnit, StatisticSource};
use crate::ao::rays::RaySet;
use crate::ao::vao::VaoSettings;
use crate::ao::{AoMethod, AoSettings};

/// Names the issue gives the AO methods; those `AoMethod::parse` accepts are offered,
/// with any others its error message lists.
const CANDIDATES: &[&str] = &[
    "none", "lao", "cao", "lao-full", "vao", "vao-live", "cdf", "gauss", "penner", "cone",
];

/// Every AO method this build knows, with its scene-file name, in a stable order.
pub fn methods() -> Vec<(String, AoMethod)> {
    let mut names: Vec<String> = CANDIDATES.iter().map(|s| (*s).to_owned()).collect();
    // The parser's error names what it accepts ("… (available: none, lao)").
    if let Err(msg) = AoMethod::parse("\u{1}")
        && let Some(list) = msg.split("available: ").nth(1)
    {
        let list = list.trim_end_matches(')');
        names.extend(list.split(',').map(|s| s.trim().to_owned()));
    }
    let mut out: Vec<(String, AoMethod)> = Vec::new();
    for n in names {
        if let Ok(m) = AoMethod::parse(&n)
            && !out.iter().any(|(_, k)| *k == m)
        {
            out.push((method_name(m), m));
        }
    }
    out
}

/// The method's name as scene files write it ("lao").
pub fn method_name(m: AoMethod) -> String {
    serde_json::to_value(m)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{m:?}").to_lowercase())
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
    ao_only: &mut bool,
    stats: &AoStats,
) -> (bool, bool) {
    let before = *settings;
    let view_before = (*ambient, *ao_only);
    egui::ComboBox::from_label("Method")
        .selected_text(method_name(settings.method))
        .show_ui(ui, |ui| {
            for (name, m) in methods() {
                ui.selectable_value(&mut settings.method, m, name);
            }
        });
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
    ui.add(egui::Slider::new(ambient, 0.0..=1.0).text("Strength k"));
    ui.checkbox(ao_only, "AO only (white, ambient term alone)");
    egui::CollapsingHeader::new("Statistics").show(ui, |ui| statistics(ui, stats));
    (*settings != before, (*ambient, *ao_only) != view_before)
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
    fn every_method_the_parser_accepts_is_listed_once() {
        let m = methods();
        assert!(m.iter().any(|(n, k)| n == "none" && *k == AoMethod::None));
        assert!(m.iter().any(|(n, k)| n == "lao" && *k == AoMethod::Lao));
        for (name, method) in &m {
            assert_eq!(AoMethod::parse(name), Ok(*method), "{name}");
            assert_eq!(m.iter().filter(|(_, k)| k == method).count(), 1);
        }
    }
}
