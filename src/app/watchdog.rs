//! The viewer's watchdog: a viewer that never settles looks the same to a user whatever
//! stopped (a job, an image, CAO's update, the drag script), so once a frame it checks
//! that what the viewer waits for moves on, and when it has not for [`STALL_REPORT`] it
//! says on stderr, once, where everything stands ([`Viewer::describe_state`]): the
//! script, the jobs, the viewport's image and CAO's update, the pacer's queue. A scripted
//! run (`--bench-clip-drag`, `--exit-after-frames`) that stays stalled for
//! [`STALL_FAIL`] ends with that as its error instead of running until it is killed.
//!
//! What counts as moving on:
//! - while the scripted drag runs: an image completed, and a CAO update completed (each
//!   on its own clock: the drag needs both);
//! - otherwise, while the viewer is busy and the view rests: a job started, ended or
//!   reported progress, an image completed, or the image being made submitted more of
//!   its rows than it ever had (one started again from its first row, over and over,
//!   does not count).
//!
//! `VOLAO_TRACE=S` prints the same line every S seconds (for a run that hangs in a way
//! the rules above miss).

use super::{STALL_FAIL, STALL_REPORT, Viewer};
use std::time::{Duration, Instant};

impl Viewer {
    /// One frame of the watchdog (see the module's documentation): traces, reports a
    /// stall once, and ends a scripted run stalled for [`STALL_FAIL`].
    pub(super) fn watch(&mut self) {
        let now = Instant::now();
        if let Some((every, last)) = self.watchdog.trace
            && last.is_none_or(|t| now - t >= every)
        {
            self.watchdog.trace = Some((every, Some(now)));
            eprintln!("volao: trace: {}", self.describe_state());
        }
        let dragging = self.scripted.bench_start.is_some() && !self.scripted.exit_requested;
        let stalled = match dragging {
            true => self.drag_stall(now),
            false => self.rest_stall(now),
        };
        let Some((since, what)) = stalled.filter(|s| s.0 >= STALL_REPORT) else {
            self.watchdog.stall = None;
            return;
        };
        if self.watchdog.stall.is_none() {
            let report = format!(
                "{what} for {:.0} s: {}",
                since.as_secs_f64(),
                self.describe_state()
            );
            eprintln!("volao: watchdog: {report}");
            self.watchdog.stall = Some(report);
        }
        let scripted =
            self.options.bench_clip_drag.is_some() || self.options.exit_after_frames.is_some();
        if scripted && since >= STALL_FAIL && !self.scripted.exit_requested {
            let state = self.describe_state();
            self.fail_exit(format!(
                "the viewer stalled ({what} for {:.0} s): {state}",
                since.as_secs_f64()
            ));
        }
    }

    /// What the watchdog reported, while the stall it reported lasts (`None`: the
    /// viewer moves on).
    pub fn stalled(&self) -> Option<&str> {
        self.watchdog.stall.as_deref()
    }

    /// While the scripted drag runs: how long since the later of an image and a CAO
    /// update last completed, and which.
    fn drag_stall(&mut self, now: Instant) -> Option<(Duration, String)> {
        self.watchdog.rest = None;
        let seen = [self.viewport.gpu.frames_rendered, self.viewport.cao_updates];
        let cao = self.viewport.gpu.has_cao();
        let last = self.watchdog.drag.get_or_insert([(0, now); 2]);
        let mut stalled = Vec::new();
        for (i, what) in ["no image", "no CAO update"].into_iter().enumerate() {
            if last[i].0 != seen[i] || (i == 1 && !cao && self.derived.cao_stats.is_none()) {
                last[i] = (seen[i], now);
            }
            if now - last[i].1 >= STALL_REPORT {
                stalled.push((now - last[i].1, what));
            }
        }
        let since = stalled.iter().map(|s| s.0).max()?;
        let what: Vec<&str> = stalled.iter().map(|s| s.1).collect();
        Some((since, format!("dragging, {}", what.join(" and "))))
    }

    /// Otherwise: how long the viewer has been busy at rest without a job moving on or
    /// its image becoming current.
    fn rest_stall(&mut self, now: Instant) -> Option<(Duration, String)> {
        self.watchdog.drag = None;
        let moving = self.viewport.motion.changed_at.elapsed() < super::viewport::INTERACTIVE_REST;
        if !self.is_busy() || moving {
            self.watchdog.rest = None;
            return None;
        }
        let jobs = self.jobs_progress();
        let image = self.viewport.gpu.work_progress();
        let images = self.viewport.gpu.frames_rendered;
        let w = &mut self.watchdog;
        let (was, since) = w.rest.get_or_insert_with(|| (jobs.clone(), now));
        // The image being made moved on: one more completed, or the same one submitted
        // more than it ever had (an image started again from its first row does not).
        let (before, made) = w.image.unwrap_or((images, None));
        let (image_moved, most) = match (made, image) {
            (Some((t, most)), Some((u, done))) if t == u => {
                (done > most, Some((t, most.max(done))))
            }
            _ => (false, image),
        };
        let image_moved = image_moved || before != images;
        w.image = Some((images, most));
        if *was != jobs || image_moved {
            *was = jobs;
            *since = now;
        }
        let since = now - *since;
        (since >= STALL_REPORT).then(|| (since, "busy at rest, nothing moved on".to_owned()))
    }

    /// The jobs running and how far each is (whole percent), in one string: a change in
    /// it is progress.
    fn jobs_progress(&self) -> String {
        let job = |label: &str, fraction: Option<f32>| {
            format!(
                "{label} {}",
                fraction.map_or(-1, |f| (100.0 * f).floor() as i32)
            )
        };
        let mut jobs = Vec::new();
        if let Some(j) = &self.opened.load_job {
            jobs.push(job(&j.label, j.fraction()));
        }
        if let Some(j) = self.derived.ao.job() {
            jobs.push(job(&j.label, j.fraction()));
        }
        if let Some(j) = self.derived.preview.job() {
            jobs.push(job(&j.label, j.fraction()));
        }
        if let Some(j) = self.derived.modulation.job() {
            jobs.push(job(&j.label, j.fraction()));
        }
        if let Some(j) = self.derived.light.job() {
            jobs.push(job(&j.label, j.fraction()));
        }
        if let Some(j) = &self.shots.write_job {
            jobs.push(job(&j.label, j.fraction()));
        }
        jobs.join(", ")
    }

    /// Where everything the viewer waits for stands, in one line: the script, the
    /// document and its jobs, the viewport's image and CAO's update, the pacer's queue.
    pub fn describe_state(&self) -> String {
        let s = &self.scripted;
        let script = match (
            self.options.bench_clip_drag,
            self.options.exit_after_frames,
            s.bench_start,
        ) {
            (Some(n), _, None) => {
                format!("--bench-clip-drag {n}: waiting for the first ready view")
            }
            (Some(n), _, Some((since, before))) => format!(
                "--bench-clip-drag {n}: dragging for {:.1} s ({} UI frames), {} images and {} \
                 CAO updates completed since it began",
                since.elapsed().as_secs_f64(),
                s.bench.len(),
                (s.images.len() as u64).saturating_sub(before),
                s.cao_updates.iter().filter(|&&t| t > since).count(),
            ),
            (None, Some(n), _) => format!("--exit-after-frames {n}: {} ready", s.ready_frames),
            (None, None, _) => "interactive".to_owned(),
        };
        let doc = match (&self.opened.doc, &self.opened.load_job) {
            (_, Some(j)) => format!(
                "loading \"{}\" ({:.0} %, {:.1} s)",
                j.label,
                100.0 * j.fraction().unwrap_or(0.0),
                j.elapsed().as_secs_f64()
            ),
            (None, None) => "no document".to_owned(),
            (Some(d), None) => format!("\"{}\" open", d.title),
        };
        let tf_waiting = self.opened.doc.as_ref().is_some_and(|d| {
            self.derived.uploaded_tf.as_ref() != Some(&(d.view_tf(), d.render.step_voxels))
        });
        let v = &self.viewport;
        let scale = match (v.interactive.on, self.want()) {
            (true, Some(w)) => self.interactive_scale(&w.frame),
            _ => 1,
        };
        format!(
            "{script}; {doc}; AO {} (shown: {:?}), preview {}, modulation {}, shadows {}{}{}; \
             viewport {}×{}: current {}, view changed {:.1} s ago, interactive scale 1/{scale}, \
             {} CAO updates so far; {}; {}",
            self.derived.ao.describe(self.ao_key().as_ref()),
            self.derived.shown,
            self.derived
                .preview
                .describe(self.preview_key(self.ao_key().as_ref()).as_ref()),
            self.derived
                .modulation
                .describe(self.modulation_key().as_ref()),
            self.derived.light.describe(self.light_key().as_ref()),
            if tf_waiting {
                ", transfer function waiting"
            } else {
                ""
            },
            if self.segments_waiting() {
                ", segments waiting"
            } else {
                ""
            },
            v.px.0,
            v.px.1,
            v.current,
            v.motion.changed_at.elapsed().as_secs_f64(),
            v.cao_updates,
            v.gpu.describe_work(),
            v.pacer.describe(),
        )
    }
}
