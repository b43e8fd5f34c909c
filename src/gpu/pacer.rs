//! [`Pacer`]: how much GPU work an interactive program may submit in one UI frame.
//!
//! wgpu has one in-order queue. Whatever the viewer submits in a frame runs before the
//! UI's own drawing of that frame, so a submission of three seconds (a CAO update on a
//! CPU adapter) freezes the window for three seconds, and a long dispatch trips Windows'
//! two-second GPU watchdog. The viewer therefore cuts long work (CAO's steps IV and V,
//! the viewport's ray cast) into pieces and keeps at most one slice of it queued: each
//! frame it submits the pieces that fit in the slice minus what is still queued.
//!
//! Pieces are converted to time with a rate per kind of work (its pass label), measured
//! on every piece: a queue callback registered just before the piece is submitted fires
//! when everything ahead of it (the UI's drawing included) is done, one registered just
//! after fires when the piece is done, and the time between them is the piece's alone. A
//! small thread polls the device every millisecond while pieces are queued so that the
//! callbacks fire on time; nothing here waits for the GPU. Rates start from what the
//! waiting runs of [`super::dispatch`] measured on the same device
//! ([`super::dispatch::Slicing::rate`]) or a low guess, so the first pieces are short on
//! any adapter and grow to the slice within a few frames on a fast one.

use super::Gpu;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A piece grows at most this much from one measurement to the next (a piece that ran
/// alone on an idle GPU says little about a full slice).
const MAX_GROWTH: f64 = 4.0;

/// How much of the earlier measurements of a kind of work each new piece keeps.
const DECAY: f64 = 0.8;

/// When the work submitted before it was made finished, stamped by a queue callback
/// (seen at a device poll).
#[derive(Debug, Clone, Default)]
pub struct Stamp(Arc<Mutex<Option<Instant>>>);

impl Stamp {
    /// A stamp for everything submitted to `gpu`'s queue so far.
    pub fn when_done(gpu: &Gpu) -> Self {
        let stamp = Stamp::default();
        let s = Arc::clone(&stamp.0);
        gpu.queue.on_submitted_work_done(move || {
            if let Ok(mut t) = s.lock() {
                *t = Some(Instant::now());
            }
        });
        stamp
    }

    /// When that work finished, once it has.
    pub fn get(&self) -> Option<Instant> {
        self.0.lock().ok().and_then(|t| *t)
    }
}

/// A submitted piece being timed.
#[derive(Debug)]
struct Piece {
    label: String,
    units: u64,
    /// Seconds the pacer expected it to take.
    estimate: f64,
    submitted: Instant,
    /// Everything submitted before it is done.
    ahead_done: Stamp,
    done: Stamp,
    /// The caller's name for it, when it wants its time back ([`Pacer::timed`]).
    tag: Option<u64>,
}

/// Polls the device every millisecond while pieces are queued, so that their callbacks
/// fire on time (a poll never waits).
#[derive(Debug)]
struct Poller {
    active: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
}

impl Poller {
    fn start(device: wgpu::Device) -> Self {
        let active = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(AtomicBool::new(false));
        let (a, s) = (Arc::clone(&active), Arc::clone(&stop));
        let spawned = std::thread::Builder::new()
            .name("volao-gpu-poll".into())
            .spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    if a.load(Ordering::Relaxed) {
                        let _ = device.poll(wgpu::PollType::Poll);
                        std::thread::sleep(Duration::from_millis(1));
                    } else {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                }
            });
        if spawned.is_err() {
            // Without the thread, pieces are timed at the UI's own polls (coarser).
            stop.store(true, Ordering::Relaxed);
        }
        Poller { active, stop }
    }
}

impl Drop for Poller {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The per-frame budget of GPU work (see the module's documentation).
#[derive(Debug)]
pub struct Pacer {
    /// GPU time of the work that may be queued at once.
    pub slice: Duration,
    /// Seconds left in this frame.
    left: f64,
    /// Work units per second, per pass label.
    rates: HashMap<String, f64>,
    /// Per pass label: units and seconds measured, each decaying with every new piece
    /// (so the rate is that of the recent work, weighted by the pieces' sizes).
    measured: HashMap<String, (f64, f64)>,
    queued: Vec<Piece>,
    /// Tagged pieces that finished since [`Pacer::timed`] last took them: label, tag and
    /// the time each took alone.
    timed: Vec<(String, u64, Duration)>,
    /// GPU time of the pieces that finished, per pass label, since [`Self::take_spent`]
    /// last took it (where a benchmark says the GPU's time went).
    spent: HashMap<String, (u64, Duration)>,
    poller: Poller,
}

impl Pacer {
    pub fn new(gpu: &Gpu, slice: Duration) -> Self {
        Pacer {
            slice,
            left: 0.0,
            rates: HashMap::new(),
            measured: HashMap::new(),
            queued: Vec::new(),
            timed: Vec::new(),
            spent: HashMap::new(),
            poller: Poller::start(gpu.device.clone()),
        }
    }

    /// Starts a UI frame: polls the device (never waits), learns the rates from the
    /// pieces that finished and opens what is left of the slice.
    pub fn begin_frame(&mut self, gpu: &Gpu) {
        let _ = gpu.device.poll(wgpu::PollType::Poll);
        let mut outstanding = 0.0;
        let mut finished: Vec<(String, u64, Duration)> = Vec::new();
        let timed = &mut self.timed;
        self.queued.retain(|p| match p.done.get() {
            Some(done) => {
                let start = p
                    .ahead_done
                    .get()
                    .map_or(p.submitted, |t| t.max(p.submitted));
                let took = done.saturating_duration_since(start);
                finished.push((p.label.clone(), p.units, took));
                if let Some(tag) = p.tag {
                    timed.push((p.label.clone(), tag, took));
                }
                false
            }
            None => {
                outstanding += p.estimate;
                true
            }
        });
        for (label, units, took) in finished {
            let spent = self.spent.entry(label.clone()).or_default();
            *spent = (spent.0 + 1, spent.1 + took);
            self.learn(&label, units, took);
        }
        self.left = self.slice.as_secs_f64() - outstanding;
        self.poller
            .active
            .store(!self.queued.is_empty(), Ordering::Relaxed);
    }

    fn learn(&mut self, label: &str, units: u64, took: Duration) {
        // A piece timed at under a millisecond is at the polls' resolution.
        let m = self.measured.entry(label.to_owned()).or_insert((0.0, 0.0));
        *m = (
            DECAY * m.0 + units as f64,
            DECAY * m.1 + took.as_secs_f64().max(1e-3),
        );
        let fresh = m.0 / m.1;
        let rate = match self.rates.get(label) {
            Some(&old) => fresh.min(old * MAX_GROWTH),
            None => fresh,
        };
        self.rates.insert(label.to_owned(), rate.max(1.0));
    }

    /// Per pass label, the pieces that finished and the GPU time they took alone since
    /// the last call (what is left of the wall-clock time is the UI's drawing and idle).
    pub fn take_spent(&mut self) -> HashMap<String, (u64, Duration)> {
        std::mem::take(&mut self.spent)
    }

    /// Whether any of this frame's slice is left.
    pub fn has_time(&self) -> bool {
        self.left > 0.0
    }

    /// Seconds left in this frame's slice (negative once overrun).
    pub fn left(&self) -> f64 {
        self.left
    }

    /// Sets `share` of what is left of this frame's slice aside (no piece takes it)
    /// and returns it, for [`Self::release`] to give back: so that work submitted later
    /// in the frame is not starved by work submitted before it.
    pub fn hold(&mut self, share: f64) -> f64 {
        let held = (self.left * share.clamp(0.0, 1.0)).max(0.0);
        self.left -= held;
        held
    }

    /// Gives back what [`Self::hold`] set aside.
    pub fn release(&mut self, held: f64) {
        self.left += held;
    }

    /// The pieces submitted with [`Self::submit_estimated`] under `label` that finished
    /// since the last call: each one's tag and the time it took alone on the GPU.
    pub fn timed(&mut self, label: &str) -> Vec<(u64, Duration)> {
        let mut out = Vec::new();
        self.timed.retain(|(l, tag, took)| {
            let mine = l == label;
            if mine {
                out.push((*tag, *took));
            }
            !mine
        });
        out
    }

    /// How many of `wanted` pieces of `label`, each costing `unit` units of work, fit in
    /// what is left of the slice (at least one when nothing is queued, so that work
    /// always moves on; none when one would overrun it). `first_rate` (units
    /// per second) is the guess for a label that neither the pacer nor the waiting runs
    /// have measured. Submit each piece with [`Self::submit`].
    pub fn take(
        &mut self,
        gpu: &Gpu,
        label: &str,
        (unit, wanted): (u64, u64),
        first_rate: f64,
    ) -> u64 {
        if self.left <= 0.0 || wanted == 0 {
            return 0;
        }
        let rate = self.rate_or(gpu, label, first_rate);
        let fit = (self.left * rate / unit.max(1) as f64).floor() as u64;
        match fit {
            0 if self.queued.is_empty() => 1,
            n => n.min(wanted),
        }
    }

    fn rate_or(&mut self, gpu: &Gpu, label: &str, first_rate: f64) -> f64 {
        *self
            .rates
            .entry(label.to_owned())
            .or_insert_with(|| gpu.slicing.rate(label).unwrap_or(first_rate).max(1.0))
    }

    /// Submits one piece of `units` of `label` (`submit` does the queue submission) and
    /// times it; its estimated time comes off the slice.
    pub fn submit<R>(
        &mut self,
        gpu: &Gpu,
        (label, units): (&str, u64),
        first_rate: f64,
        submit: impl FnOnce() -> R,
    ) -> R {
        let rate = self.rate_or(gpu, label, first_rate);
        self.submit_piece(gpu, (label, units), units as f64 / rate, None, submit)
    }

    /// Submits one piece of `units` of `label` that the caller expects to take
    /// `estimate` seconds (it knows better than the label's mean rate: the strips of an
    /// image through the volume cost many times those beside it); its time comes back
    /// from [`Self::timed`] under `tag`. The label's rate is learnt from it as usual.
    pub fn submit_estimated<R>(
        &mut self,
        gpu: &Gpu,
        (label, units): (&str, u64),
        (estimate, tag): (f64, u64),
        submit: impl FnOnce() -> R,
    ) -> R {
        self.submit_piece(gpu, (label, units), estimate, Some(tag), submit)
    }

    fn submit_piece<R>(
        &mut self,
        gpu: &Gpu,
        (label, units): (&str, u64),
        estimate: f64,
        tag: Option<u64>,
        submit: impl FnOnce() -> R,
    ) -> R {
        self.left -= estimate;
        let ahead_done = Stamp::when_done(gpu);
        let submitted = Instant::now();
        let r = submit();
        self.queued.push(Piece {
            label: label.to_owned(),
            units,
            estimate,
            submitted,
            ahead_done,
            done: Stamp::when_done(gpu),
            tag,
        });
        self.poller.active.store(true, Ordering::Relaxed);
        r
    }

    /// What is queued and what is left of the slice, in one line (the scripted runs'
    /// watchdog says it when nothing has moved for a long time).
    pub fn describe(&self) -> String {
        let now = Instant::now();
        let pieces: Vec<String> = self
            .queued
            .iter()
            .map(|p| {
                format!(
                    "{} ({:.1} ms expected, queued {:.1} s ago, ahead {})",
                    p.label,
                    p.estimate * 1e3,
                    (now - p.submitted).as_secs_f64(),
                    match p.ahead_done.get() {
                        Some(_) => "done",
                        None => "not done",
                    }
                )
            })
            .collect();
        let mut rates: Vec<String> = self
            .rates
            .iter()
            .map(|(label, rate)| format!("{label} {rate:.3e}/s"))
            .collect();
        rates.sort();
        format!(
            "pacer: {:.1} ms of the slice left, {} pieces queued [{}], rates [{}]",
            self.left * 1e3,
            self.queued.len(),
            pieces.join("; "),
            rates.join(", ")
        )
    }

    /// Whether pieces are still queued.
    pub fn busy(&self) -> bool {
        !self.queued.is_empty()
    }

    /// The rate (units per second) the pacer uses for `label`, once it has used it.
    pub fn rate(&self, label: &str) -> Option<f64> {
        self.rates.get(label).copied()
    }
}
