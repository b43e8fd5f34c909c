//! [`Variant`]: which ray-caster pipeline draws a frame (the `override` constants of
//! `shaders/raycast.wgsl`); [`super::gpu::RayCaster`] builds one per variant in use.

use super::Frame;
use super::gpu_volume::RenderVolume;

/// What a frame's pipeline is specialised for: the `override` constants of
/// `shaders/raycast.wgsl`. A feature that is off is left out of the shader (on lavapipe
/// a branch not taken still costs its work); what is on is still decided per frame by
/// the uniforms, so every variant draws the same pixels as the general shader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Variant {
    /// [`super::RenderMode::code`].
    pub mode: u32,
    pub phong: bool,
    /// An AO volume is bound (not the 1×1×1 texel of 1).
    pub ao_volume: bool,
    pub live_vao: bool,
    pub shadows: bool,
    pub surfaces: bool,
    pub clip: bool,
    /// The number of clip shapes the pipeline is built for (`CLIP_SHAPES` of
    /// `clip_common.wgsl`); 0: any (read from the uniforms).
    pub clip_shapes: u32,
    /// An opacity-modulation volume is bound (not the 1×1×1 texel of 1).
    pub modulation: bool,
    pub skipping: bool,
    /// A gradient volume is bound (one fetch per gradient instead of six); `None`: the
    /// uniform `box_half.w` decides (the general shader).
    pub gradient: Option<bool>,
    /// A segmentation is read (`SEGMENTS` of `volume.wgsl`), with its colour modes
    /// (`SEGMENT_MODES`) and whether its weight has edges (`SEGMENT_EDGES`).
    pub segments: bool,
    pub segment_modes: u32,
    pub segment_edges: bool,
    /// Some class's weight is below 1 (`SEGMENT_WEIGHTS`).
    pub segment_weights: bool,
    /// The ray stops where it first reaches the pick's opacity and says where (`PICK`).
    pub pick: bool,
    /// A visibility pass (`MARK_AO`, [`crate::ao::view`]): AO reads mark voxels.
    pub mark_ao: bool,
}

impl Variant {
    /// The variant that draws `frame` of `vol` with `clip` and the surface layer (or not).
    pub fn of(
        vol: &RenderVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        surfaces: bool,
    ) -> Variant {
        let s = &frame.settings;
        // Only composite and iso shade their samples (and only composite modulates):
        // the projections get one pipeline whatever the lighting settings.
        let lit = s.mode.uses_ao();
        let shadows = lit && vol.extras.light.is_some();
        let phong = lit && s.shading == super::Shading::Phong;
        let ao_volume = lit && vol.ao_bound;
        let live_vao = lit && vol.extras.live_vao.is_some();
        Variant {
            mode: s.mode.code(),
            phong,
            ao_volume,
            live_vao,
            shadows,
            // With shadows, the surface code stays in: lavapipe (Mesa 22.3.6) segfaults
            // in a worker thread running Phong pipelines that read the light volume and
            // neither the surfaces nor live AO in group 2 (composite and iso seen). The
            // surfaces' uniform flag still decides, so the pixels are the same.
            surfaces: surfaces || shadows,
            clip: clip.is_some_and(|c| c.uniforms.counts[0] > 0),
            clip_shapes: clip.map_or(0, |c| c.uniforms.counts[0]),
            modulation: s.mode.is_composite() && vol.modulation_bound,
            skipping: s.empty_space_skipping,
            // Only shading and the AO's read point take gradients: without either, the
            // same pipeline whether a gradient volume is bound or not.
            gradient: Some(vol.gradient_volume().is_some() && (phong || ao_volume || live_vao)),
            segments: vol.segments.on,
            segment_modes: vol.segments.modes,
            segment_edges: vol.segments.edges && (phong || ao_volume || live_vao),
            segment_weights: vol.segments.edges,
            pick: false,
            mark_ao: false,
        }
    }

    /// The visibility pass of `frame`: the pipeline that draws it once its AO volume is
    /// bound (every sample, read offset and termination the same), marking the voxels its
    /// AO reads weigh instead of using the image.
    pub fn marking(
        vol: &RenderVolume,
        frame: &Frame,
        clip: Option<&crate::clip::gpu::ClipMaps>,
        surfaces: bool,
    ) -> Variant {
        let v = Variant::of(vol, frame, clip, surfaces);
        let lit = frame.settings.mode.uses_ao();
        let phong = v.phong;
        let gradient = Some(vol.gradient_volume().is_some() && lit);
        Variant {
            ao_volume: lit,
            gradient: if lit { gradient } else { v.gradient },
            segment_edges: vol.segments.edges && (phong || lit || v.live_vao),
            mark_ao: lit,
            ..v
        }
    }

    /// Every feature compiled in, as the shader's defaults: the uniforms decide alone.
    pub fn general(mode: super::RenderMode) -> Variant {
        Variant {
            mode: mode.code(),
            phong: true,
            ao_volume: true,
            live_vao: true,
            shadows: true,
            surfaces: true,
            clip: true,
            clip_shapes: 0,
            modulation: true,
            skipping: true,
            gradient: None,
            segments: true,
            segment_modes: 2,
            segment_edges: true,
            segment_weights: true,
            pick: false,
            mark_ao: false,
        }
    }

    /// The values of the shader's `override` constants.
    pub(super) fn constants(&self) -> [(&'static str, f64); 18] {
        let b = |on: bool| f64::from(u8::from(on));
        // Shading that fetches: worth finding a sample with opacity before shading.
        let find = self.phong || self.ao_volume || self.live_vao || self.shadows || self.modulation;
        [
            ("FIND", b(find)),
            ("MODE", f64::from(self.mode)),
            ("PHONG", b(self.phong)),
            ("AO_VOLUME", b(self.ao_volume)),
            ("LIVE_VAO", b(self.live_vao)),
            ("SHADOWS", b(self.shadows)),
            ("SURFACES", b(self.surfaces)),
            ("CLIP", b(self.clip)),
            ("CLIP_SHAPES", f64::from(self.clip_shapes)),
            ("MODULATION", b(self.modulation)),
            ("SKIPPING", b(self.skipping)),
            ("GRADIENT", self.gradient.map_or(2.0, b)),
            ("SEGMENTS", b(self.segments)),
            ("SEGMENT_MODES", f64::from(self.segment_modes)),
            ("SEGMENT_EDGES", b(self.segment_edges)),
            ("SEGMENT_WEIGHTS", b(self.segment_weights)),
            ("PICK", b(self.pick)),
            ("MARK_AO", b(self.mark_ao)),
        ]
    }
}
