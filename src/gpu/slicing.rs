//! [`Slicing`]: how long one submission of a long stage may take in an interactive
//! program, from the throughput measured per pass label (see [`super::dispatch`]).

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Duration;

/// Time-sliced submissions for an interactive program (the viewer). With a slice time
/// set, the dispatchers size each submission of a long stage from the throughput they
/// measured for it (work units per second, per pass label) so that it takes about that
/// long, and wait for it before submitting the next, so that the UI's frames slip in
/// between. Without one (the CLI, the tests), submissions are as large as the work
/// budgets allow. The size of a submission never changes a result: every voxel is
/// computed by one invocation, whichever submission it falls in.
#[derive(Debug, Default)]
pub struct Slicing {
    target: Mutex<Option<Duration>>,
    /// Measured units per second, per pass label.
    rates: Mutex<HashMap<String, f64>>,
}

/// Throughput assumed for a stage before its first submission was measured (samples per
/// second, about lavapipe's on two cores): the first slice is short on any adapter, the
/// following ones grow to the slice time.
const FIRST_RATE: f64 = 1e8;

/// A slice grows at most this much from one submission to the next.
const MAX_GROWTH: f64 = 4.0;

/// How much of the best rate seen survives each new measurement.
const RATE_DECAY: f64 = 0.95;

impl Slicing {
    /// Sets (or with `None` removes) the time one submission may take.
    pub fn set_target(&self, target: Option<Duration>) {
        *self.target.lock().unwrap_or_else(|e| e.into_inner()) = target;
    }

    pub fn target(&self) -> Option<Duration> {
        *self.target.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether submissions are sliced in time.
    pub fn is_on(&self) -> bool {
        self.target().is_some()
    }

    /// The measured throughput of `label` (units per second), if any.
    pub fn rate(&self, label: &str) -> Option<f64> {
        self.rates
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(label)
            .copied()
    }

    /// Units of work of `label` that fit in `time` (at least 1, at most `max`).
    pub fn units_in(&self, label: &str, time: Duration, max: u64) -> u64 {
        let rate = self.rate(label).unwrap_or(FIRST_RATE);
        ((rate * time.as_secs_f64()) as u64).clamp(1, max.max(1))
    }

    /// Units of work of `label` for the next submission: `max` without a slice time.
    pub fn units(&self, label: &str, max: u64) -> u64 {
        match self.target() {
            None => max.max(1),
            Some(t) => self.units_in(label, t, max),
        }
    }

    /// Records that `units` of `label` took `took` (submission to completion).
    ///
    /// The time includes whatever ran ahead of the submission on the queue (the UI's
    /// frames, the viewport's slices), which says nothing about this work's speed: taken
    /// at face value it would shrink the next submission, whose fixed costs then weigh
    /// more, and so on down to single bricks. So the rate kept is the best one seen,
    /// decaying slowly to follow a device that got slower.
    pub fn measured(&self, label: &str, units: u64, took: Duration) {
        let fresh = units as f64 / took.as_secs_f64().max(1e-5);
        let mut rates = self.rates.lock().unwrap_or_else(|e| e.into_inner());
        let rate = match rates.get(label) {
            Some(&old) => fresh.max(old * RATE_DECAY).min(old * MAX_GROWTH),
            None => fresh.clamp(FIRST_RATE, FIRST_RATE * MAX_GROWTH),
        };
        rates.insert(label.to_owned(), rate);
    }
}
