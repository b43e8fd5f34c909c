//! Scripted runs of the viewer: `--bench-clip-drag N` (drags the first clip shape and
//! reports the UI's frame times, the viewport's images and CAO's updates) and
//! `--exit-after-frames N [--screenshot PNG]` (closes once the volume and its AO have
//! been shown N times, after writing the screenshot).

use super::Viewer;
use super::screenshot::ShotSize;
use std::time::Instant;

/// CAO updates `--bench-clip-drag` waits for while dragging (besides its images), so that
/// it can say how far apart they came (four intervals: one slow one moves the mean less).
const MIN_CAO_UPDATES: usize = 5;

impl Viewer {
    /// Starts `--bench-clip-drag n` now, or again once it has ended (tests repeat the
    /// scripted drag on one viewer without computing its AO again): from the next frame
    /// the viewport alone fills the window, and the drag begins once it shows a ready
    /// view.
    pub fn start_clip_drag(&mut self, n: u64) {
        self.options.bench_clip_drag = Some(n);
        self.scripted = Default::default();
        if let Ok(mut e) = self.exit_error.lock() {
            *e = None;
        }
        self.ctx.request_repaint();
    }

    /// How the scripted run ended: `None` while it runs (or without one), else `Ok` or
    /// the error it ended with (the watchdog's, when it stalled).
    pub fn scripted_outcome(&self) -> Option<Result<(), String>> {
        if !self.scripted.exit_requested {
            return None;
        }
        let error = self.exit_error.lock().ok().and_then(|e| e.clone());
        Some(error.map_or(Ok(()), Err))
    }

    /// One frame of `--bench-clip-drag N`: once the view is ready, moves the first clip
    /// shape every UI frame (back and forth by 1 mm, a slow drag) and measures the UI
    /// frames (what the mouse feels) and the viewport's images (each exact for its
    /// pose) until N images have come while dragging.
    pub(super) fn bench_step(&mut self, ctx: &egui::Context) {
        let Some(n) = self.options.bench_clip_drag else {
            return;
        };
        ctx.request_repaint();
        self.fail_on_ao_error();
        if self.close_if_requested(ctx) {
            return;
        }
        let now = Instant::now();
        let ready = self.shows_ready_view();
        let share = self.cao_percent_recomputed();
        let cao = share.is_some();
        let (reused, rendered) = (self.viewport_images_reused(), self.viewport_images());
        let b = &mut self.scripted;
        if b.bench_start.is_none() {
            // Start once the first full-quality image with AO is on screen.
            if !ready {
                return;
            }
            b.bench_start = Some((now, b.images.len() as u64));
            self.viewport.pacer.take_spent();
            b.bench_last = Some(now);
        }
        let Some((since, images_before)) = b.bench_start else {
            return;
        };
        if let Some(last) = b.bench_last {
            b.bench.push((now - last).as_secs_f64());
        }
        b.bench_last = Some(now);
        // The first two images after the drag starts were begun before it: not counted.
        let counted = b.images.iter().skip(images_before as usize + 2);
        let images: Vec<Instant> = counted.clone().map(|i| i.0).collect();
        let mut scales = std::collections::BTreeMap::<u32, usize>::new();
        for i in counted {
            *scales.entry(i.2).or_default() += 1;
        }
        // CAO's updates (each for the newest pose when it began) completed while dragging;
        // the first was begun before.
        let updates: Vec<Instant> = b
            .cao_updates
            .iter()
            .filter(|&&t| t > since)
            .skip(1)
            .copied()
            .collect();
        if images.len() as u64 > n && (!cao || updates.len() >= MIN_CAO_UPDATES) {
            let mut between: Vec<f64> = images
                .windows(2)
                .map(|w| (w[1] - w[0]).as_secs_f64())
                .collect();
            between.sort_by(f64::total_cmp);
            let mean = between.iter().sum::<f64>() / between.len() as f64;
            let mut ui = b.bench.clone();
            ui.sort_by(f64::total_cmp);
            let pct = |p: usize| ui[((ui.len() * p).div_ceil(100)).clamp(1, ui.len()) - 1];
            let elapsed = (images[images.len() - 1] - images[0])
                .as_secs_f64()
                .max(1e-9);
            println!(
                "viewport {}×{}: {} images while dragging a clip shape, mean {:.0} ms, median \
                 {:.0} ms, min {:.0} ms between images; CAO recomputed {:.2} % of voxels in \
                 the last update; {}",
                self.viewport.px.0,
                self.viewport.px.1,
                between.len(),
                mean * 1e3,
                between[between.len() / 2] * 1e3,
                between[0] * 1e3,
                share.unwrap_or(0.0),
                self.gpu.describe()
            );
            println!(
                "ui frame p50 {:.0} ms p95 {:.0} ms over {} frames; viewport {:.1} updates/s; \
                 {:.1} s dragging",
                pct(50) * 1e3,
                pct(95) * 1e3,
                ui.len(),
                between.len() as f64 / elapsed,
                since.elapsed().as_secs_f64()
            );
            let scales: Vec<String> = scales
                .iter()
                .map(|(s, n)| format!("{n} at 1/{s}"))
                .collect();
            println!(
                "images that cast only the rays near a change and kept the rest: {reused} of \
                 {rendered}; the drag's images by size on each axis: {}",
                scales.join(", ")
            );
            // Where the GPU's time went: each label's pieces, timed alone.
            let wall = since.elapsed().as_secs_f64();
            let mut spent: Vec<_> = self.viewport.pacer.take_spent().into_iter().collect();
            spent.sort_by_key(|s| std::cmp::Reverse(s.1.1));
            let busy: f64 = spent.iter().map(|s| s.1.1.as_secs_f64()).sum();
            let parts: Vec<String> = spent
                .iter()
                .map(|(label, (n, t))| {
                    let t = t.as_secs_f64();
                    format!(
                        "{label} {:.1} % ({n} pieces, {:.1} ms each)",
                        100.0 * t / wall,
                        1e3 * t / *n as f64
                    )
                })
                .collect();
            println!(
                "GPU time while dragging, pieces timed alone: {}; the rest ({:.1} %) the UI's drawing and idle",
                parts.join(", "),
                100.0 * (1.0 - busy / wall).max(0.0)
            );
            if cao {
                let mut apart: Vec<f64> = updates
                    .windows(2)
                    .map(|w| (w[1] - w[0]).as_secs_f64() * 1e3)
                    .collect();
                apart.sort_by(f64::total_cmp);
                println!(
                    "CAO updates while dragging: {}, mean {:.0} ms apart (median {:.0}, {:.0} to {:.0})",
                    updates.len(),
                    apart.iter().sum::<f64>() / apart.len().max(1) as f64,
                    apart.get(apart.len() / 2).copied().unwrap_or(0.0),
                    apart.first().copied().unwrap_or(0.0),
                    apart.last().copied().unwrap_or(0.0),
                );
            }
            self.scripted.exit_requested = true;
            return;
        }
        if let Some(doc) = &mut self.opened.doc
            && let Some(s) = doc.clip_shapes.first_mut()
        {
            // Back and forth by 1 mm per UI frame, as a slow drag.
            let dir = if (self.scripted.bench.len() / 8).is_multiple_of(2) {
                1.0
            } else {
                -1.0
            };
            s.translation[0] += dir;
        } else {
            self.fail_exit("--bench-clip-drag needs a scene with a clip shape".into());
        }
    }

    /// `--exit-after-frames N [--screenshot PNG]`: count frames that show the volume with
    /// its AO, then take the screenshot and close once it is written.
    pub(super) fn exit_logic(&mut self, ctx: &egui::Context) {
        if self.close_if_requested(ctx) {
            return;
        }
        let Some(n) = self.options.exit_after_frames else {
            return;
        };
        if self.fail_on_ao_error() {
            return;
        }
        if self.shows_ready_view() {
            self.scripted.ready_frames += 1;
        }
        if self.scripted.ready_frames < n {
            ctx.request_repaint();
            return;
        }
        if self.scripted.ready_frames == n {
            match self.options.screenshot.clone() {
                Some(path) => self.request_screenshot(path, ShotSize::Window),
                None => self.scripted.exit_requested = true,
            }
        }
        ctx.request_repaint();
    }

    /// Closes the window once a scripted run has finished (or failed); true if it did.
    fn close_if_requested(&mut self, ctx: &egui::Context) -> bool {
        if self.scripted.exit_requested {
            self.chrome.quit_confirmed = true;
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
        self.scripted.exit_requested
    }

    /// Ends a scripted run with the AO's error, if the AO failed; true if it did.
    fn fail_on_ao_error(&mut self) -> bool {
        let Some(e) = self.ao_error() else {
            return false;
        };
        let message = format!("ambient occlusion failed: {e}");
        self.fail_exit(message);
        true
    }

    /// The volume, the volumes derived from it and the full-quality image of what the
    /// document says are on screen.
    fn shows_ready_view(&self) -> bool {
        self.opened.doc.is_some()
            && self.opened.load_job.is_none()
            && self.derived_ready()
            && self.viewport.current
    }
}
