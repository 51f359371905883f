//! The worker pool: a dispatcher takes the oldest queued job from the database
//! whenever fewer than `workers` jobs are tracking, and runs it on a blocking thread
//! (the engine is synchronous CPU work, kept off the async runtime) with the same
//! `track_clip` as `monocap track`. Each tracked frame becomes a `progress` event on
//! the bus; a flusher writes them and the job's progress to the database twice a
//! second. Cancellation, the per-job time limit and shutdown are checked after every
//! frame.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::json;
use tokio::sync::{Notify, Semaphore};
use tokio_util::sync::CancellationToken;
use tracing::Instrument;

use super::bus::{numbered, Bus, Live};
use super::options::JobOptions;
use crate::motion::files::{write_model_masks, write_motion, MotionFormat};
use crate::store::blobs::Blobs;
use crate::store::{Artifact, Event, Job, JobError, JobState, Outcome, ProgressRow, Store};

/// What the pool may do.
#[derive(Clone, Debug)]
pub struct PoolConfig {
    /// Jobs tracking at once (at most the machine's cores).
    pub workers: usize,
    /// Attempts before a job that keeps dying with the process is failed.
    pub max_attempts: u32,
    /// Longest a job may track.
    pub job_timeout: Option<Duration>,
    /// Caps on what a clip may make the decoder allocate.
    pub limits: crate::clip::Limits,
    /// Scratch space for jobs' files before they are stored.
    pub work_dir: PathBuf,
}

/// Why a running job should stop, and a flag the engine polls (per frame while
/// decoding, per tracked frame while tracking).
struct Stop {
    why: AtomicU8,
    flag: Arc<AtomicBool>,
}

impl Stop {
    fn new(why: u8) -> Stop {
        Stop {
            why: AtomicU8::new(why),
            flag: Arc::new(AtomicBool::new(why != GO)),
        }
    }

    /// Asks the job to stop for `why` (the first reason wins).
    fn halt(&self, why: u8) {
        let _ = self
            .why
            .compare_exchange(GO, why, Ordering::SeqCst, Ordering::SeqCst);
        self.flag.store(true, Ordering::SeqCst);
    }

    fn why(&self) -> u8 {
        self.why.load(Ordering::SeqCst)
    }
}

const GO: u8 = 0;
const CANCEL: u8 = 1;
const SHUTDOWN: u8 = 2;
const TIMEOUT: u8 = 3;

/// The files a finished job makes, with their content types.
pub const ARTIFACTS: [(&str, &str); 3] = [
    ("motion.bvh", "application/octet-stream"),
    ("motion.json", "application/json"),
    ("model_masks.zip", "application/zip"),
];

/// The jobs side of the service: store, files, bus and the pool.
pub struct Jobs {
    pub store: Arc<dyn Store>,
    pub blobs: Blobs,
    pub bus: Bus,
    pub cfg: PoolConfig,
    running: Mutex<HashMap<String, Arc<Stop>>>,
    wake: Notify,
    pub shutdown: CancellationToken,
}

/// The blob key of a job's file.
pub fn artifact_key(job: &str, name: &str) -> String {
    format!("jobs/{job}/{name}")
}

impl Jobs {
    pub fn new(store: Arc<dyn Store>, blobs: Blobs, cfg: PoolConfig) -> Jobs {
        Jobs {
            store,
            blobs,
            bus: Bus::new(),
            cfg,
            running: Mutex::new(HashMap::new()),
            wake: Notify::new(),
            shutdown: CancellationToken::new(),
        }
    }

    /// Tells the dispatcher a job was queued.
    pub fn wake(&self) {
        self.wake.notify_one();
    }

    /// The job's live log, opened if needed with numbers after the stored events.
    pub async fn live(&self, id: &str) -> anyhow::Result<Arc<Live>> {
        if let Some(l) = self.bus.get(id) {
            return Ok(l);
        }
        let last = self.store.last_event_seq(id).await?;
        Ok(self.bus.open(id, last + 1))
    }

    /// Stores events and then publishes them.
    pub async fn record(
        &self,
        id: &str,
        events: Vec<(&str, serde_json::Value)>,
    ) -> anyhow::Result<Vec<Event>> {
        let live = self.live(id).await?;
        let events = live.prepare(events);
        self.store.append_events(id, events.clone()).await?;
        live.publish(&events);
        Ok(events)
    }

    /// Moves a job from one of `from` to a final state, storing and publishing the
    /// final events (`state`, then `done` or `failed`). False when the job was in
    /// none of those states.
    pub async fn finish(
        &self,
        job: &str,
        from: &[JobState],
        outcome: Outcome,
    ) -> anyhow::Result<bool> {
        // A job tracking in this process has a live log that numbers its events; any
        // other is numbered after what is stored (opening a log here would leave one
        // nobody closes when the job is not in `from`).
        let live = self.bus.get(job);
        let final_event = match outcome.state {
            JobState::Succeeded => (
                "done",
                json!({ "state": "succeeded", "artifacts": outcome.artifacts }),
            ),
            s => (
                "failed",
                json!({ "state": s.as_str(), "error": outcome.error }),
            ),
        };
        let list = vec![
            ("state", json!({ "state": outcome.state.as_str() })),
            final_event,
        ];
        let events = match &live {
            Some(l) => l.prepare(list),
            None => numbered(self.store.last_event_seq(job).await? + 1, list),
        };
        let done = self
            .store
            .finish(job, from, outcome, events.clone())
            .await?;
        if done {
            if let Some(l) = &live {
                l.publish(&events);
            }
            self.bus.remove(job);
            self.bus.changed();
        }
        Ok(done)
    }

    /// Cancels a job: a queued one at once, a running one within a frame. False when
    /// it had already ended.
    pub async fn cancel(&self, job: &Job) -> anyhow::Result<bool> {
        if job.state.is_final() {
            return Ok(false);
        }
        self.store.request_cancel(&job.id).await?;
        let canceled = Outcome {
            state: JobState::Canceled,
            error: Some(JobError {
                code: "canceled".into(),
                message: "the job was canceled".into(),
            }),
            artifacts: vec![],
        };
        if self.finish(&job.id, &[JobState::Queued], canceled).await? {
            return Ok(true);
        }
        if let Some(flag) = self
            .running
            .lock()
            .ok()
            .and_then(|m| m.get(&job.id).cloned())
        {
            flag.halt(CANCEL);
        }
        Ok(true)
    }

    /// Runs queued jobs until shutdown, then stops the running ones within a frame
    /// (they go back to the queue for the next start) and waits for them.
    pub async fn run(self: Arc<Self>) {
        let workers = self.cfg.workers.max(1);
        let slots = Arc::new(Semaphore::new(workers));
        loop {
            let permit = tokio::select! {
                p = slots.clone().acquire_owned() => match p { Ok(p) => p, Err(_) => break },
                _ = self.shutdown.cancelled() => break,
            };
            match self.store.claim_next().await {
                Ok(Some(job)) => {
                    let me = self.clone();
                    // Everything the job logs, here and on its tracking thread, is
                    // in its span.
                    let span = tracing::info_span!("job", id = %job.id, attempt = job.attempts);
                    tokio::spawn(
                        async move {
                            if let Err(e) = me.clone().run_job(job).await {
                                tracing::error!("job bookkeeping failed: {e:#}");
                            }
                            drop(permit);
                        }
                        .instrument(span),
                    );
                }
                Ok(None) => {
                    drop(permit);
                    tokio::select! {
                        _ = self.wake.notified() => {}
                        _ = tokio::time::sleep(Duration::from_secs(2)) => {}
                        _ = self.shutdown.cancelled() => break,
                    }
                }
                Err(e) => {
                    drop(permit);
                    tracing::error!("cannot read the queue: {e}");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
        if let Ok(m) = self.running.lock() {
            for stop in m.values() {
                stop.halt(SHUTDOWN);
            }
        }
        let _ = slots.acquire_many(workers as u32).await;
    }

    async fn run_job(self: Arc<Self>, job: Job) -> anyhow::Result<()> {
        let id = job.id.clone();
        let stop = Arc::new(Stop::new(if job.cancel_requested { CANCEL } else { GO }));
        if let Ok(mut m) = self.running.lock() {
            m.insert(id.clone(), stop.clone());
        }
        // Open the job's live log now, not at its first event: a subscriber that
        // finds none polls the database, and a job canceled and deleted before its
        // first frame would take its final events with it before the next poll.
        if let Err(e) = self.live(&id).await {
            tracing::warn!("cannot open the job's live log: {e:#}");
        }
        // A cancel or a shutdown between the claim and the line above found nothing
        // to flag: look again now that the flag is there.
        if self.cancel_recorded(&id).await {
            stop.halt(CANCEL);
        }
        if self.shutdown.is_cancelled() {
            stop.halt(SHUTDOWN);
        }
        tracing::info!(clip = %job.clip_name, bytes = job.clip_bytes, "tracking");
        metrics::gauge!("monocap_jobs_running").increment(1.0);
        let result = self.clone().track(&job, stop.clone()).await;
        metrics::gauge!("monocap_jobs_running").decrement(1.0);
        if let Ok(mut m) = self.running.lock() {
            m.remove(&id);
        }
        let why = stop.why();
        let outcome = match result {
            Ok(artifacts) => Outcome {
                state: JobState::Succeeded,
                error: None,
                artifacts,
            },
            Err(_) if why == SHUTDOWN => {
                self.store.requeue(&id).await?;
                self.record(
                    &id,
                    vec![(
                        "state",
                        json!({ "state": "queued", "reason": "the service is restarting" }),
                    )],
                )
                .await?;
                tracing::info!("back in the queue for the next start");
                return Ok(());
            }
            Err(e) => {
                let (state, code, message) = match why {
                    CANCEL => (
                        JobState::Canceled,
                        "canceled",
                        "the job was canceled".into(),
                    ),
                    TIMEOUT => (
                        JobState::Failed,
                        "time_limit",
                        format!(
                            "tracking took longer than the limit of {} s",
                            self.cfg.job_timeout.map_or(0, |d| d.as_secs())
                        ),
                    ),
                    _ => (JobState::Failed, e.code, e.message),
                };
                Outcome {
                    state,
                    error: Some(JobError {
                        code: code.into(),
                        message,
                    }),
                    artifacts: vec![],
                }
            }
        };
        tracing::info!(state = outcome.state.as_str(), "job ended");
        metrics::counter!("monocap_jobs_finished_total", "state" => outcome.state.as_str())
            .increment(1);
        // The outcome must reach the database, or the job would look running until
        // the next start: retry through passing database trouble.
        let mut wait = Duration::from_millis(200);
        loop {
            match self
                .finish(&id, &[JobState::Running], outcome.clone())
                .await
            {
                Ok(_) => return Ok(()),
                Err(e) if !self.shutdown.is_cancelled() => {
                    tracing::warn!("cannot store the job's outcome, retrying: {e:#}");
                    tokio::time::sleep(wait).await;
                    wait = (wait * 2).min(Duration::from_secs(10));
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Tracks the job's clip and stores its files.
    async fn track(self: Arc<Self>, job: &Job, stop: Arc<Stop>) -> Result<Vec<Artifact>, Failure> {
        let id = job.id.clone();
        let live = self.live(&id).await.map_err(Failure::internal)?;
        self.record(
            &id,
            vec![(
                "state",
                json!({ "state": "running", "attempt": job.attempts }),
            )],
        )
        .await
        .map_err(Failure::internal)?;
        let options: JobOptions = serde_json::from_value(job.options.clone())
            .map_err(|e| Failure::new("bad_options", format!("stored options: {e}")))?;
        let mut opts = options
            .to_track()
            .map_err(|e| Failure::new("bad_options", e))?;
        opts.limits = self.cfg.limits.clone();
        opts.silhouettes.stop = Some(stop.flag.clone());
        opts.track.stop = Some(stop.flag.clone());
        let clip = self
            .blobs
            .local_path(&job.clip_key)
            .map_err(Failure::internal)?;
        let work = self.cfg.work_dir.join(&id);
        let _ = std::fs::remove_dir_all(&work);
        std::fs::create_dir_all(&work).map_err(|e| Failure::internal(e.into()))?;
        let deadline = self.cfg.job_timeout.map(|d| Instant::now() + d);
        let progress = Arc::new(Mutex::new(None::<ProgressRow>));

        let blocking = {
            let (live, stop, progress, work, clip_name) = (
                live.clone(),
                stop.clone(),
                progress.clone(),
                work.clone(),
                job.clip_name.clone(),
            );
            let span = tracing::Span::current();
            tokio::task::spawn_blocking(move || -> Result<(), Failure> {
                let _span = span.enter();
                let done = crate::track::run::track_clip(&clip, &opts, |f, p| {
                    live.emit(
                        "progress",
                        json!({
                            "frame": f.index,
                            "frames_done": p.frames_done,
                            "frames_total": p.frames_total,
                            "person": f.person,
                            "cost": f.cost,
                            "iou": f.iou,
                            "fps": p.fps,
                            "revised": p.revised,
                        }),
                    );
                    if !p.revised {
                        metrics::counter!("monocap_frames_tracked_total").increment(1);
                    }
                    if let Ok(mut g) = progress.lock() {
                        *g = Some(ProgressRow {
                            frames_done: p.frames_done as u64,
                            frames_total: p.frames_total.map(|t| t as u64),
                            fps: p.fps,
                        });
                    }
                    if deadline.is_some_and(|d| Instant::now() > d) {
                        stop.halt(TIMEOUT);
                    }
                    if stop.why() == GO {
                        std::ops::ControlFlow::Continue(())
                    } else {
                        std::ops::ControlFlow::Break(())
                    }
                })
                .map_err(|e| {
                    let path = clip.display().to_string();
                    Failure::new(
                        "tracking_failed",
                        format!("{e:#}").replace(&path, &clip_name),
                    )
                })?;
                for w in &done.warnings {
                    tracing::warn!("{w}");
                    live.emit("warning", json!({ "message": w }));
                }
                write_motion(&done, MotionFormat::Bvh, &work.join("motion.bvh"))
                    .and_then(|()| {
                        write_motion(&done, MotionFormat::Json, &work.join("motion.json"))
                    })
                    .and_then(|()| write_model_masks(&done, &work.join("model_masks.zip")))
                    .map_err(Failure::internal)
            })
        };
        tokio::pin!(blocking);
        let mut tick = tokio::time::interval(Duration::from_millis(500));
        let joined = loop {
            tokio::select! {
                r = &mut blocking => break r,
                _ = tick.tick() => {
                    // The limit also holds while the clip is decoded, before any frame.
                    if deadline.is_some_and(|d| Instant::now() > d) {
                        stop.halt(TIMEOUT);
                    }
                    // A cancel that reached another node sharing the database.
                    if self.cancel_recorded(&id).await {
                        stop.halt(CANCEL);
                    }
                    self.flush(&id, &live, &progress).await
                }
            }
        };
        self.flush(&id, &live, &progress).await;
        let result = match joined {
            Ok(r) => r,
            Err(_) => Err(Failure::new(
                "internal",
                "the tracker stopped unexpectedly (a bug; please report it with the clip)",
            )),
        };
        let stored = match result {
            Ok(()) => self.store_artifacts(&id, &work).await,
            Err(e) => Err(e),
        };
        let _ = std::fs::remove_dir_all(&work);
        stored
    }

    async fn store_artifacts(
        &self,
        id: &str,
        work: &std::path::Path,
    ) -> Result<Vec<Artifact>, Failure> {
        let mut out = Vec::new();
        for (name, content_type) in ARTIFACTS {
            let bytes = self
                .blobs
                .put_file(&artifact_key(id, name), &work.join(name))
                .await
                .map_err(Failure::internal)?;
            out.push(Artifact {
                name: name.into(),
                bytes,
                content_type: content_type.into(),
            });
        }
        Ok(out)
    }

    /// Whether the database holds a cancel for the job (made by a request this
    /// process has not flagged, or by another node).
    async fn cancel_recorded(&self, id: &str) -> bool {
        matches!(self.store.job(id).await, Ok(Some(j)) if j.cancel_requested)
    }

    /// Writes the events and progress not yet in the database.
    async fn flush(&self, id: &str, live: &Live, progress: &Mutex<Option<ProgressRow>>) {
        let events = live.unstored();
        if let Some(last) = events.last().map(|e| e.seq) {
            // Marked stored only once they are: a failed write is retried next time.
            match self.store.append_events(id, events).await {
                Ok(()) => live.mark_stored(last),
                Err(e) => tracing::warn!(job = %id, "cannot store progress events: {e}"),
            }
        }
        let p = progress.lock().ok().and_then(|mut g| g.take());
        if let Some(p) = p {
            if let Err(e) = self.store.set_progress(id, p).await {
                tracing::warn!(job = %id, "cannot store progress: {e}");
            }
        }
    }
}

/// Why a job failed.
#[derive(Debug)]
struct Failure {
    code: &'static str,
    message: String,
}

impl Failure {
    fn new(code: &'static str, message: impl Into<String>) -> Failure {
        Failure {
            code,
            message: message.into(),
        }
    }

    fn internal(e: anyhow::Error) -> Failure {
        tracing::error!("internal error in a job: {e:#}");
        Failure::new(
            "internal",
            format!("the service failed to run the job: {e:#}"),
        )
    }
}
