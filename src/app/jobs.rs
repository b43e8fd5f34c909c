//! Long work off the UI thread: loading a file, AO precomputation, writing screenshots.
//!
//! A [`Job`] runs a closure on its own thread and hands back its result through a
//! channel; the closure reports progress through [`Progress`], which also asks egui to
//! repaint so the progress bar moves. Cancel is cooperative: the next progress report
//! after [`Job::cancel`] unwinds the worker with a private payload (no panic message),
//! so loaders and AO code that only take a progress callback stop at their next report.
//!
//! [`Keyed`] is the one mechanism for results kept on the GPU and recomputed when what
//! they depend on changes (AO, opacity modulation, the light volume of shadows).

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::{Duration, Instant};

/// Why a job produced no result.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JobError {
    #[error("cancelled")]
    Cancelled,
    #[error("{0}")]
    Failed(String),
}

/// The payload a cancelled worker unwinds with.
struct Cancelled;

/// Progress and cancellation shared between a job and the UI.
pub struct Progress {
    done: AtomicU64,
    total: AtomicU64,
    cancel: AtomicBool,
    repaint: Box<dyn Fn() + Send + Sync>,
    /// When a progress report last asked for a repaint (ms since `born`).
    repainted_ms: AtomicU64,
    born: Instant,
}

/// Progress reports ask for a repaint at most this often: a job reporting every few
/// milliseconds would otherwise keep the UI drawing (on a CPU adapter, drawing the
/// window takes the cores the job's GPU work needs).
const PROGRESS_REPAINT: Duration = Duration::from_millis(100);

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("done", &self.done)
            .field("total", &self.total)
            .field("cancel", &self.cancel)
            .finish_non_exhaustive()
    }
}

impl Progress {
    fn new(repaint: Box<dyn Fn() + Send + Sync>) -> Self {
        Progress {
            done: AtomicU64::new(0),
            total: AtomicU64::new(0),
            cancel: AtomicBool::new(false),
            repaint,
            repainted_ms: AtomicU64::new(0),
            born: Instant::now(),
        }
    }

    /// Reports `done` of `total` units; stops the job here if it was cancelled.
    pub fn set(&self, done: u64, total: u64) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(done, Ordering::Relaxed);
        let now = self.born.elapsed().as_millis() as u64;
        let last = self.repainted_ms.load(Ordering::Relaxed);
        if now >= last + PROGRESS_REPAINT.as_millis() as u64
            && self
                .repainted_ms
                .compare_exchange(last, now, Ordering::Relaxed, Ordering::Relaxed)
                .is_ok()
        {
            (self.repaint)();
        }
        self.check();
    }

    /// Stops the job here if it was cancelled.
    pub fn check(&self) {
        if self.cancel.load(Ordering::Relaxed) {
            resume_unwind(Box::new(Cancelled));
        }
    }

    /// Fraction done in [0, 1], or `None` before the first report.
    pub fn fraction(&self) -> Option<f32> {
        let total = self.total.load(Ordering::Relaxed);
        (total > 0).then(|| (self.done.load(Ordering::Relaxed) as f64 / total as f64) as f32)
    }
}

/// A closure running on a worker thread.
#[derive(Debug)]
pub struct Job<T> {
    /// What the progress bar says ("loading engine.raw").
    pub label: String,
    progress: Arc<Progress>,
    rx: Receiver<Result<T, JobError>>,
    started: Instant,
}

impl<T: Send + 'static> Job<T> {
    /// Starts `work` on a new thread; `repaint` is called on every progress report and
    /// when the job ends (the viewer passes `egui::Context::request_repaint`).
    pub fn spawn(
        label: impl Into<String>,
        repaint: impl Fn() + Send + Sync + 'static,
        work: impl FnOnce(&Progress) -> Result<T, String> + Send + 'static,
    ) -> Self {
        let label = label.into();
        let progress = Arc::new(Progress::new(Box::new(repaint)));
        let (tx, rx) = channel();
        let p = Arc::clone(&progress);
        let spawned = std::thread::Builder::new()
            .name(format!("volao job: {label}"))
            .spawn(move || {
                let result = match catch_unwind(AssertUnwindSafe(|| work(&p))) {
                    Ok(r) => r.map_err(JobError::Failed),
                    Err(payload) if payload.is::<Cancelled>() => Err(JobError::Cancelled),
                    Err(payload) => Err(JobError::Failed(format!(
                        "internal error: {}",
                        panic_message(payload.as_ref())
                    ))),
                };
                let _ = tx.send(result);
                (p.repaint)();
            });
        let job = Job {
            label,
            progress,
            rx,
            started: Instant::now(),
        };
        if let Err(e) = spawned {
            // No thread: report the failure through the job itself.
            let (tx, rx) = channel();
            let _ = tx.send(Err(JobError::Failed(format!(
                "could not start a worker thread: {e}"
            ))));
            return Job { rx, ..job };
        }
        job
    }

    /// The result once the job has ended (`None` while it runs).
    pub fn poll(&mut self) -> Option<Result<T, JobError>> {
        match self.rx.try_recv() {
            Ok(r) => Some(r),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => Some(Err(JobError::Failed(
                "the worker thread ended without a result".into(),
            ))),
        }
    }

    /// Waits at most `timeout` for the result (tests and the CLI; never the UI thread).
    pub fn wait(&mut self, timeout: Duration) -> Option<Result<T, JobError>> {
        self.rx.recv_timeout(timeout).ok()
    }
}

impl<T> Job<T> {
    /// Asks the job to stop at its next progress report.
    pub fn cancel(&self) {
        self.progress.cancel.store(true, Ordering::Relaxed);
    }

    pub fn fraction(&self) -> Option<f32> {
        self.progress.fraction()
    }

    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a worker thread panicked".into())
}

/// What [`Keyed::poll`] found.
#[derive(Debug)]
pub enum Polled<K, T> {
    /// Nothing finished (or a result for a key since left, dropped).
    Nothing,
    /// The result for `K`, still wanted: apply it, then [`Keyed::uploaded`] (or
    /// [`Keyed::fail`] when it cannot be applied).
    Ready(K, T),
    /// The computation failed; the message is kept for [`Keyed::error`].
    Failed(String),
}

/// Something the viewer derives from the document in the background and keeps on the GPU
/// (the AO volume or CAO's state, the opacity modulation factors, the light volume),
/// keyed by what it is computed for: the key of what the GPU has, the job computing the
/// next one, and a failure, kept (not retried) until the wanted key changes.
///
/// Each frame the owner [`poll`](Self::poll)s with the key it wants now and applies a
/// `Ready` result. While the state is not [`settled`](Self::settled) for that key it
/// [`reset`](Self::reset)s (clearing the GPU's copy, or keeping it on screen until the
/// next one arrives) and [`start`](Self::start)s a job; a value made at once on the UI
/// thread is simply [`uploaded`](Self::uploaded).
#[derive(Debug)]
pub struct Keyed<K, T> {
    on_gpu: Option<K>,
    job: Option<(K, Job<T>)>,
    failed: Option<(K, String)>,
}

impl<K, T> Default for Keyed<K, T> {
    fn default() -> Self {
        Keyed {
            on_gpu: None,
            job: None,
            failed: None,
        }
    }
}

impl<K: Clone + PartialEq, T: Send + 'static> Keyed<K, T> {
    /// Whether the GPU has what `want` asks for (`None`: nothing wanted, nothing there).
    pub fn ready(&self, want: Option<&K>) -> bool {
        self.on_gpu.as_ref() == want
    }

    /// What the GPU has.
    pub fn on_gpu(&self) -> Option<&K> {
        self.on_gpu.as_ref()
    }

    /// Why the computation for `want` failed, if it did.
    pub fn error(&self, want: Option<&K>) -> Option<&str> {
        let (key, message) = self.failed.as_ref()?;
        (Some(key) == want).then_some(message.as_str())
    }

    /// The job running, if any (its label and progress for the status bar).
    pub fn job(&self) -> Option<&Job<T>> {
        self.job.as_ref().map(|(_, job)| job)
    }

    /// Whether a job is running.
    pub fn computing(&self) -> bool {
        self.job.is_some()
    }

    /// Whether work for `want` remains: a job runs, or `want` is neither on the GPU nor
    /// failed.
    pub fn pending(&self, want: Option<&K>) -> bool {
        self.computing() || !self.ready(want) && self.error(want).is_none()
    }

    /// Whether nothing more is to be done for `want`: ready, being computed or failed;
    /// with nothing wanted, nothing on the GPU, running or failed.
    pub fn settled(&self, want: Option<&K>) -> bool {
        match want {
            None => self.on_gpu.is_none() && self.job.is_none() && self.failed.is_none(),
            Some(_) => {
                self.ready(want)
                    || self.job.as_ref().is_some_and(|(k, _)| Some(k) == want)
                    || self.error(want).is_some()
            }
        }
    }

    /// Collects a finished job.
    pub fn poll(&mut self, want: Option<&K>) -> Polled<K, T> {
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
            Ok(value) => Polled::Ready(key, value),
            Err(JobError::Cancelled) => Polled::Nothing,
            Err(JobError::Failed(message)) => {
                self.failed = Some((key, message.clone()));
                Polled::Failed(message)
            }
        }
    }

    /// Records that the result for `key` is on the GPU.
    pub fn uploaded(&mut self, key: K) {
        self.on_gpu = Some(key);
    }

    /// Records that `key` failed (a result that could not be applied, a job the user
    /// cancelled): not retried until the wanted key changes.
    pub fn fail(&mut self, key: K, message: String) {
        self.failed = Some((key, message));
    }

    /// Stops the running job, if any.
    pub fn cancel(&mut self) {
        if let Some((_, job)) = self.job.take() {
            job.cancel();
        }
    }

    /// Cancels the job and forgets the failure and what the GPU has; true when the GPU
    /// had something (which the caller clears, or keeps on screen until the next result).
    pub fn reset(&mut self) -> bool {
        self.cancel();
        self.failed = None;
        self.on_gpu.take().is_some()
    }

    /// Runs `job` for `key`.
    pub fn start(&mut self, key: K, job: Job<T>) {
        self.job = Some((key, job));
    }

    /// Where it stands for `want`, in a few words (for the viewer's watchdog): on the
    /// GPU, computing (how far, for how long, and whether for `want`), failed or nothing.
    pub fn describe(&self, want: Option<&K>) -> String {
        let state = match (&self.job, want) {
            (Some((key, job)), _) => format!(
                "\"{}\" {} for {:.1} s{}",
                job.label,
                job.fraction()
                    .map_or("started".to_owned(), |f| format!("{:.0} %", 100.0 * f)),
                job.elapsed().as_secs_f64(),
                if Some(key) == want {
                    ""
                } else {
                    " (for other settings)"
                }
            ),
            (None, None) => "none wanted".to_owned(),
            (None, Some(_)) if self.ready(want) => "ready".to_owned(),
            (None, Some(_)) => match self.error(want) {
                Some(e) => format!("failed: {e}"),
                None => "wanted, not started".to_owned(),
            },
        };
        match self.on_gpu.is_some() && !self.ready(want) {
            true => format!("{state}, a stale one on the GPU"),
            false => state,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_progress_and_cancel() {
        let mut ok = Job::spawn(
            "sum",
            || {},
            |p| {
                p.set(1, 2);
                Ok(41 + 1)
            },
        );
        assert_eq!(ok.wait(Duration::from_secs(10)), Some(Ok(42)));

        let mut failing: Job<()> = Job::spawn("fail", || {}, |_| Err("bad file".into()));
        assert_eq!(
            failing.wait(Duration::from_secs(10)),
            Some(Err(JobError::Failed("bad file".into())))
        );

        // A job that reports forever stops at the first report after cancel.
        let (started_tx, started_rx) = channel();
        let mut endless: Job<()> = Job::spawn(
            "endless",
            || {},
            move |p| {
                p.set(1, 10);
                let _ = started_tx.send(());
                loop {
                    p.set(1, 10);
                    std::thread::sleep(Duration::from_millis(1));
                }
            },
        );
        started_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("job started");
        assert_eq!(endless.fraction(), Some(0.1));
        assert!(endless.poll().is_none(), "still running");
        endless.cancel();
        assert_eq!(
            endless.wait(Duration::from_secs(10)),
            Some(Err(JobError::Cancelled))
        );
    }

    /// Polls until the job ends.
    fn finish<T: Send + 'static>(k: &mut Keyed<u32, T>, want: Option<&u32>) -> Polled<u32, T> {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let polled = k.poll(want);
            if !k.computing() || Instant::now() > deadline {
                return polled;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    #[test]
    fn keyed_drops_stale_results_and_keeps_a_failure_until_the_key_changes() {
        let mut k: Keyed<u32, u32> = Keyed::default();
        assert!(k.settled(None) && !k.pending(None));
        assert!(!k.settled(Some(&1)) && k.pending(Some(&1)));

        k.start(1, Job::spawn("one", || {}, |_| Err("bad file".into())));
        assert!(k.settled(Some(&1)), "being computed");
        assert!(matches!(finish(&mut k, Some(&1)), Polled::Failed(m) if m == "bad file"));
        assert_eq!(k.error(Some(&1)), Some("bad file"));
        assert!(k.settled(Some(&1)) && !k.pending(Some(&1)), "not retried");
        assert!(!k.settled(None), "nothing wanted: the failure goes");
        assert!(!k.reset(), "nothing was on the GPU");
        assert_eq!(k.error(Some(&1)), None);

        // A result for a key since left is dropped.
        k.start(2, Job::spawn("two", || {}, |_| Ok(2)));
        assert!(matches!(finish(&mut k, Some(&3)), Polled::Nothing));
        assert!(!k.computing() && !k.ready(Some(&2)));

        k.start(3, Job::spawn("three", || {}, |_| Ok(30)));
        assert!(matches!(finish(&mut k, Some(&3)), Polled::Ready(3, 30)));
        k.uploaded(3);
        assert!(k.ready(Some(&3)) && k.settled(Some(&3)) && !k.pending(Some(&3)));
        assert_eq!(k.on_gpu(), Some(&3));
        assert!(!k.settled(None) && k.reset(), "the GPU had something");
        assert!(k.settled(None));
    }
}
