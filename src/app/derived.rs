//! Per-voxel volumes the viewer derives from the document in the background and uploads
//! when ready (the opacity modulation factors, the light volume of shadows), each keyed
//! by what it was computed for: a stale one is dropped at once, never shown for other
//! settings.

use super::jobs::{Job, JobError};

/// What [`Derived::poll`] found.
#[derive(Debug)]
pub enum Polled<K> {
    /// Nothing finished (or a result for settings since left, dropped).
    Nothing,
    /// Values for `K`, still wanted: upload them, then [`Derived::uploaded`].
    Ready(K, Vec<f32>),
    /// The computation failed; the message is kept for [`Derived::error`].
    Failed(String),
}

/// One derived volume: what is on the GPU, the job computing the next one, and settings
/// whose computation failed (not retried until they change).
#[derive(Debug)]
pub struct Derived<K> {
    on_gpu: Option<K>,
    job: Option<(K, Job<Vec<f32>>)>,
    failed: Option<(K, String)>,
}

impl<K> Default for Derived<K> {
    fn default() -> Self {
        Derived {
            on_gpu: None,
            job: None,
            failed: None,
        }
    }
}

impl<K: Clone + PartialEq> Derived<K> {
    /// Whether the GPU has what `want` asks for (`None`: nothing wanted, nothing there).
    pub fn ready(&self, want: Option<&K>) -> bool {
        self.on_gpu.as_ref() == want
    }

    /// Why the computation for `want` failed, if it did.
    pub fn error(&self, want: Option<&K>) -> Option<&str> {
        let (key, message) = self.failed.as_ref()?;
        (Some(key) == want).then_some(message.as_str())
    }

    /// Whether a job is running.
    pub fn computing(&self) -> bool {
        self.job.is_some()
    }

    /// Whether nothing more is to be done for `want`: ready, being computed or failed.
    pub fn settled(&self, want: Option<&K>) -> bool {
        self.ready(want)
            || self.job.as_ref().is_some_and(|(k, _)| Some(k) == want)
            || self.error(want).is_some()
    }

    /// Collects a finished job.
    pub fn poll(&mut self, want: Option<&K>) -> Polled<K> {
        let Some((key, job)) = &mut self.job else {
            return Polled::Nothing;
        };
        let Some(result) = job.poll() else {
            return Polled::Nothing;
        };
        let key = key.clone();
        self.job = None;
        match result {
            Ok(_) if Some(&key) != want => Polled::Nothing,
            Ok(values) => Polled::Ready(key, values),
            Err(JobError::Cancelled) => Polled::Nothing,
            Err(JobError::Failed(message)) => {
                self.failed = Some((key, message.clone()));
                Polled::Failed(message)
            }
        }
    }

    /// Records that the values for `key` are on the GPU.
    pub fn uploaded(&mut self, key: K) {
        self.on_gpu = Some(key);
    }

    /// Cancels the job and forgets what the GPU has; true when it had something (which
    /// the caller then clears).
    pub fn reset(&mut self) -> bool {
        if let Some((_, job)) = self.job.take() {
            job.cancel();
        }
        self.on_gpu.take().is_some()
    }

    /// Runs `job` for `key`.
    pub fn start(&mut self, key: K, job: Job<Vec<f32>>) {
        self.job = Some((key, job));
    }
}
