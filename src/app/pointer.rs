//! The viewer's hover line: [`super::hover`]'s walk along the ray under the pointer,
//! run when the pointer moved over the viewport or what is under it changed.

use super::Viewer;
use super::hover::{HoverKey, class_under};
use crate::sample::{SegmentSampler, VolumeSampler, bake_lut};

impl Viewer {
    /// Names the segments under the pointer when it moved over the viewport (or what is
    /// under it changed); not while a button is down (dragging the view or a shape).
    pub(super) fn update_hover(&mut self, ui: &egui::Ui) {
        let rect = self.viewport.rect;
        let (pos, down) = ui.input(|i| (i.pointer.hover_pos(), i.pointer.any_down()));
        let pos = pos.filter(|p| rect.contains(*p));
        let built = self.derived.segments.as_ref().filter(|b| b.uploaded);
        let (Some(pos), Some(doc), Some(built), Some(frame)) =
            (pos, &self.opened.doc, built, self.view_frame())
        else {
            self.chrome.hover.key = None;
            self.chrome.hover.text = None;
            return;
        };
        if down {
            return;
        }
        let ppp = ui.ctx().pixels_per_point();
        let px = [
            ((pos.x - rect.min.x) * ppp).max(0.0) as u32,
            ((pos.y - rect.min.y) * ppp).max(0.0) as u32,
        ];
        let key = HoverKey {
            px,
            frame,
            clip: doc.clip_shapes.clone(),
            tf: doc.view_tf(),
            segments: built.version,
            generation: self.opened.generation,
        };
        let hover = &mut self.chrome.hover;
        if hover.key.as_ref() == Some(&key) {
            return;
        }
        let (Some(g), Some(seg)) = (&self.viewport.gpu.volume, &doc.segmentation) else {
            return;
        };
        let Some(segment_texels) = &g.segment_texels else {
            return;
        };
        let texels = &g.texels;
        if hover
            .norm
            .as_ref()
            .is_none_or(|(n, _)| *n != key.generation)
        {
            hover.norm = Some((key.generation, texels.norm_values()));
        }
        let step = frame.settings.step_voxels;
        if hover
            .lut
            .as_ref()
            .is_none_or(|(k, _)| *k != (key.tf.clone(), step))
        {
            hover.lut = Some(((key.tf.clone(), step), bake_lut(&key.tf, texels, step)));
        }
        if hover
            .sampler
            .as_ref()
            .is_none_or(|(v, _)| *v != key.segments)
        {
            hover.sampler = Some((key.segments, SegmentSampler::new(segment_texels)));
        }
        let (Some((_, norm)), Some((_, lut)), Some((_, sampler))) =
            (&hover.norm, &hover.lut, &hover.sampler)
        else {
            return;
        };
        let params = frame.params(texels, lut, 0, 0);
        let volume = VolumeSampler::density(norm, texels, lut).with_segments(Some(sampler));
        let class = class_under(&params, &volume, sampler, &doc.clip_shapes, px);
        hover.text = class.map(|c| match seg.classes.members.get(c) {
            Some(members) => seg.names(members),
            None => format!("class {c}"),
        });
        hover.key = Some(key);
    }
}
