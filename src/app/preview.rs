//! Progressive AO: while a slow AO is computed (LAO, CAO's `V_PAO`, positional AO, cone
//! tracing), the viewport shows a cheap ambient term — the Gaussian ambient map of the
//! transfer function's opacity from the CPU twin of the filter maps, tens of
//! milliseconds on the demo head — and swaps in the exact one when it is ready. The
//! status bar says which is shown ([`super::derived::AoShown`]).

use super::Viewer;
use super::derived::{AoKey, AoShown};
use super::jobs::{Job, Polled};
use crate::ao::filter::{RadiusUnit, StatisticSource};
use crate::ao::{Ambient, AoEngine, AoInput, AoMethod, AoRequest, AoSettings};
use crate::texels::VolumeTexels;
use crate::tf::TransferFunction;
use std::sync::Arc;

/// Whether `method` is slow enough to be previewed by an ambient map (the ambient maps
/// are that cheap term themselves; live positional AO needs no precomputation).
pub fn has_preview(method: AoMethod) -> bool {
    matches!(
        method,
        AoMethod::Lao | AoMethod::Cao | AoMethod::LaoFull | AoMethod::Vao | AoMethod::Cone
    )
}

/// The ambient map that stands in for `settings`: Gaussian, of the opacity, over a box
/// as wide as the method's reach.
pub fn preview_settings(settings: &AoSettings) -> AoSettings {
    let reach_mm = match settings.method {
        AoMethod::Vao => settings.vao.r_max_mm,
        _ => settings.samples as f32,
    };
    AoSettings {
        method: AoMethod::Gauss,
        radius: reach_mm.max(1.0),
        radius_unit: RadiusUnit::Mm,
        statistic: StatisticSource::Opacity,
        ..*settings
    }
}

/// The ambient map for `settings` on the CPU twin (fast on every machine, and it leaves
/// the GPU's queue to the viewport).
pub fn compute_preview(
    texels: &VolumeTexels,
    tf: &TransferFunction,
    settings: &AoSettings,
) -> Result<Vec<f32>, String> {
    let s = preview_settings(settings);
    let request = AoRequest {
        tf,
        settings: &s,
        clip: None,
        coverage: crate::ao::sparse::Coverage::Every,
        view: None,
    };
    let computed = AoEngine::on(None)
        .compute(AoInput::Texels(texels), &request, &|_, _| {})
        .map_err(|e| e.to_string())?;
    match computed.ambient {
        Ambient::Values(v) => Ok(v),
        _ => Err("the ambient map came back in an unexpected form".into()),
    }
}

impl Viewer {
    /// What the viewport shows as its ambient term.
    pub fn ao_shown(&self) -> AoShown {
        self.derived.shown
    }

    /// The preview the current settings want: their key while the exact AO is not on the
    /// GPU and the method is slow.
    pub(super) fn preview_key(&self, want: Option<&AoKey>) -> Option<AoKey> {
        want.filter(|k| has_preview(k.settings.method) && !self.derived.ao.ready(Some(k)))
            .cloned()
    }

    /// Collects a finished ambient map and shows it while the exact AO is not ready.
    pub(super) fn poll_preview(&mut self, want: Option<&AoKey>) {
        let preview = self.preview_key(want);
        match self.derived.preview.poll(preview.as_ref()) {
            Polled::Nothing => {}
            Polled::Ready(key, values) => {
                let gpu = Arc::clone(&self.gpu);
                let v = &mut self.viewport.gpu;
                let fits = v
                    .volume
                    .as_mut()
                    .filter(|g| values.len() == g.texels.dims.iter().product::<usize>());
                let shown = fits.is_some();
                if let Some(g) = fits {
                    g.set_ambient_occlusion(&gpu, &values);
                    v.set_cao(None);
                }
                if shown {
                    self.derived.preview.uploaded(key);
                    self.derived.shown = AoShown::Approximate;
                }
            }
            // The exact AO is still coming; the approximation is only a courtesy.
            Polled::Failed(message) => eprintln!("volao: the AO preview failed: {message}"),
        }
    }

    /// Starts the ambient map for the current settings when one is wanted and neither
    /// shown nor computing. Unlike the exact AO it does not wait for the transfer
    /// function to rest: it is cheap and follows the curve while it is dragged.
    pub(super) fn start_preview(&mut self, want: Option<&AoKey>) {
        let Some(key) = self.preview_key(want) else {
            self.derived.preview.cancel();
            return;
        };
        if self.derived.preview.settled(Some(&key)) {
            return;
        }
        self.derived.preview.reset();
        let (Some(doc), Some(texels)) = (&self.opened.doc, self.uploaded_texels()) else {
            return;
        };
        let (tf, settings) = (doc.tf.clone(), key.settings);
        let job = Job::spawn("AO preview", self.repaint_fn(), move |_| {
            compute_preview(&texels, &tf, &settings)
        });
        self.derived.preview.start(key, job);
    }

    /// The status bar's words for [`AoShown`], `None` with AO off.
    pub(super) fn ao_shown_text(&self) -> Option<String> {
        let method = self.opened.doc.as_ref()?.ao.method;
        match self.derived.shown {
            AoShown::Nothing if method == AoMethod::None => None,
            AoShown::Nothing => Some(format!("AO: none yet ({} computing)", method.label())),
            AoShown::Previous => Some("AO: previous, updating…".into()),
            AoShown::Approximate => Some(format!(
                "AO: approximate (ambient map) until {} is ready",
                method.label()
            )),
            AoShown::Exact => Some(format!("AO: {}", method.label())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_methods_are_previewed_by_a_gaussian_map_of_their_reach() {
        assert!(has_preview(AoMethod::Cao) && has_preview(AoMethod::Lao));
        assert!(!has_preview(AoMethod::Gauss) && !has_preview(AoMethod::VaoLive));
        let lao = AoSettings {
            method: AoMethod::Lao,
            samples: 16,
            ..AoSettings::default()
        };
        let p = preview_settings(&lao);
        assert_eq!(p.method, AoMethod::Gauss);
        assert_eq!((p.radius, p.radius_unit), (16.0, RadiusUnit::Mm));
        let vol = crate::volume::demo::head_phantom(16).to_ras();
        let texels = VolumeTexels::new(&vol, crate::texels::UploadLimits::NONE);
        let stats = vol.stats();
        let tf = TransferFunction::preset(crate::tf::Preset::default_for(&stats), &stats);
        let a = compute_preview(&texels, &tf, &lao).expect("preview");
        assert_eq!(a.len(), 16 * 16 * 16);
        assert!(a.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(a.iter().any(|v| *v < 0.99), "the map occludes somewhere");
    }
}
