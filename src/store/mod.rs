//! What the service keeps: jobs, their progress events and API keys in a database
//! (behind [`Store`]; SQLite is the embedded default, PostgreSQL the shared one), clips and motion files in a
//! blob store ([`blobs::Blobs`]).

pub mod blobs;
pub mod sql;

use futures_util::future::BoxFuture;
use serde::{Deserialize, Serialize};

/// A job's life: `queued` → `running` → one of the three final states. A running
/// job whose process died goes back to `queued` at the next start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Canceled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Succeeded,
        JobState::Failed,
        JobState::Canceled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Canceled => "canceled",
        }
    }

    pub fn parse(s: &str) -> Option<JobState> {
        JobState::ALL.into_iter().find(|j| j.as_str() == s)
    }

    pub fn is_final(self) -> bool {
        matches!(
            self,
            JobState::Succeeded | JobState::Failed | JobState::Canceled
        )
    }
}

/// Why a job failed: a stable code and a message for people.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobError {
    pub code: String,
    pub message: String,
}

/// A file a finished job made.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Artifact {
    pub name: String,
    pub bytes: u64,
    pub content_type: String,
}

/// A job as stored.
#[derive(Clone, Debug)]
pub struct Job {
    pub id: String,
    pub owner: String,
    pub state: JobState,
    /// The options as submitted (JSON object).
    pub options: serde_json::Value,
    /// Where the clip is in the blob store.
    pub clip_key: String,
    pub clip_name: String,
    pub clip_bytes: u64,
    /// The clip's probe (contracts.md `probe` JSON).
    pub clip_info: serde_json::Value,
    pub idempotency_key: Option<String>,
    pub rerun_of: Option<String>,
    pub attempts: u32,
    pub cancel_requested: bool,
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    pub fps: Option<f64>,
    pub error: Option<JobError>,
    pub artifacts: Vec<Artifact>,
    /// Milliseconds since the Unix epoch.
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub updated_at: i64,
    /// Bumped on every change.
    pub version: i64,
}

/// A job to insert.
#[derive(Clone, Debug)]
pub struct NewJob {
    pub id: String,
    pub owner: String,
    pub options: serde_json::Value,
    pub clip_key: String,
    pub clip_name: String,
    pub clip_bytes: u64,
    pub clip_info: serde_json::Value,
    pub idempotency_key: Option<String>,
    pub rerun_of: Option<String>,
}

/// What [`Store::insert_job`] did.
#[derive(Debug)]
pub enum Inserted {
    New(Job),
    /// A job with the same owner and idempotency key already exists.
    Existing(Job),
}

/// One event of a job's stream; `seq` increases per job and never repeats.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Event {
    pub seq: i64,
    pub kind: String,
    pub data: serde_json::Value,
}

/// An API key (its token is never stored, only a hash of it).
#[derive(Clone, Debug, Serialize)]
pub struct ApiKey {
    pub id: String,
    pub name: String,
    pub created_at: i64,
}

/// Filters of [`Store::list_jobs`].
#[derive(Clone, Debug, Default)]
pub struct JobFilter {
    /// Only this owner's jobs.
    pub owner: Option<String>,
    pub state: Option<JobState>,
    /// Only jobs older than this id (the cursor of the previous page).
    pub before: Option<String>,
    /// Only the job with this idempotency key.
    pub idempotency_key: Option<String>,
    pub limit: u32,
}

/// What a running job reports as it goes.
#[derive(Clone, Copy, Debug, Default)]
pub struct ProgressRow {
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    pub fps: f64,
}

/// A job's final state with what it made.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub state: JobState,
    pub error: Option<JobError>,
    pub artifacts: Vec<Artifact>,
}

/// What a start-up recovery did with a job the previous process left running.
#[derive(Clone, Debug)]
pub struct Recovered {
    pub id: String,
    pub state: JobState,
    pub attempts: u32,
}

pub type StoreResult<T> = Result<T, sqlx::Error>;

/// The service's database. Handlers and workers see only this trait, so a second
/// database (PostgreSQL) is a second implementation, not a change to them.
pub trait Store: Send + Sync + 'static {
    /// Inserts a queued job with its first event (number 1, `state` queued), or
    /// returns the existing one with the same owner and idempotency key.
    fn insert_job(&self, job: NewJob) -> BoxFuture<'_, StoreResult<Inserted>>;
    fn job(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<Job>>>;
    /// Newest first.
    fn list_jobs(&self, filter: JobFilter) -> BoxFuture<'_, StoreResult<Vec<Job>>>;
    /// How many queued jobs come before this one (None when it is not queued).
    fn queue_position(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<u64>>>;
    fn count_by_state(&self) -> BoxFuture<'_, StoreResult<Vec<(JobState, u64)>>>;
    /// The oldest queued job, now running (its attempt counted).
    fn claim_next(&self) -> BoxFuture<'_, StoreResult<Option<Job>>>;
    fn set_progress(&self, id: &str, p: ProgressRow) -> BoxFuture<'_, StoreResult<()>>;
    fn append_events(&self, id: &str, events: Vec<Event>) -> BoxFuture<'_, StoreResult<()>>;
    /// Events with `seq` above `after`, in order, at most `limit`.
    fn events_after(
        &self,
        id: &str,
        after: i64,
        limit: u32,
    ) -> BoxFuture<'_, StoreResult<Vec<Event>>>;
    fn last_event_seq(&self, id: &str) -> BoxFuture<'_, StoreResult<i64>>;
    /// Moves a job that is in one of the states `from` into a final state, with its
    /// last events, in one transaction. False when it was in none of them.
    fn finish(
        &self,
        id: &str,
        from: &[JobState],
        outcome: Outcome,
        events: Vec<Event>,
    ) -> BoxFuture<'_, StoreResult<bool>>;
    /// Puts a running job back in the queue without counting its attempt (the
    /// service is shutting down).
    fn requeue(&self, id: &str) -> BoxFuture<'_, StoreResult<()>>;
    /// Marks a running job for cancellation (its worker stops within a frame).
    fn request_cancel(&self, id: &str) -> BoxFuture<'_, StoreResult<()>>;
    /// Deletes the job and its events; returns it as it was.
    fn delete_job(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<Job>>>;
    /// How many jobs use the blob at `clip_key`.
    fn clip_users(&self, clip_key: &str) -> BoxFuture<'_, StoreResult<u64>>;
    /// At start-up: jobs left `running` go back to `queued`, or fail once they have
    /// used `max_attempts`.
    fn recover(&self, max_attempts: u32) -> BoxFuture<'_, StoreResult<Vec<Recovered>>>;
    fn create_key(
        &self,
        id: &str,
        name: &str,
        token_hash: &str,
    ) -> BoxFuture<'_, StoreResult<ApiKey>>;
    fn key_by_hash(&self, token_hash: &str) -> BoxFuture<'_, StoreResult<Option<ApiKey>>>;
    fn count_keys(&self) -> BoxFuture<'_, StoreResult<u64>>;
    /// Whether the database answers.
    fn ping(&self) -> BoxFuture<'_, StoreResult<()>>;
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}
