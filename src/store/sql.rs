//! [`Store`] on SQL through sqlx's `Any` driver: the same queries serve SQLite (the
//! embedded default: one file, write-ahead log) and PostgreSQL (a database server;
//! the queries are safe for several nodes, but files still live in each node's data
//! folder, so one node per data folder for now). Each has its migrations (`migrations/sqlite`,
//! `migrations/postgres`), applied at open. The SQL is the common dialect of both:
//! `$N` parameters, `ON CONFLICT`, `RETURNING`.

use std::path::Path;
use std::time::Duration;

use futures_util::future::BoxFuture;
use sqlx::any::{AnyPoolOptions, AnyRow};
use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::SqlStr;
use sqlx::{AnyPool, Executor, Row};

use super::{
    now_ms, ApiKey, Artifact, Event, Inserted, Job, JobError, JobFilter, JobState, NewJob, Outcome,
    ProgressRow, Recovered, Store, StoreResult,
};

/// Which database a [`SqlStore`] talks to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

pub struct SqlStore {
    pool: AnyPool,
    pub backend: Backend,
}

impl SqlStore {
    /// Opens (creating if needed) an SQLite database file.
    pub async fn open_sqlite(path: &Path) -> anyhow::Result<SqlStore> {
        SqlStore::connect(&format!("sqlite://{}?mode=rwc", path.display())).await
    }

    /// Connects to `sqlite://PATH` or `postgres://…` and brings the schema up to
    /// date.
    pub async fn connect(url: &str) -> anyhow::Result<SqlStore> {
        sqlx::any::install_default_drivers();
        let backend = if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Backend::Postgres
        } else if url.starts_with("sqlite:") {
            Backend::Sqlite
        } else {
            anyhow::bail!("database URL {url:?}: expected sqlite://PATH or postgres://…");
        };
        let shown = redact(url);
        let pool = AnyPoolOptions::new()
            .max_connections(if backend == Backend::Sqlite { 8 } else { 16 })
            .after_connect(move |conn, _| {
                Box::pin(async move {
                    if backend == Backend::Sqlite {
                        // Readers never block the writer; wait for locks, do not fail.
                        conn.execute("PRAGMA journal_mode = WAL").await?;
                        conn.execute("PRAGMA synchronous = NORMAL").await?;
                        conn.execute("PRAGMA busy_timeout = 10000").await?;
                        conn.execute("PRAGMA foreign_keys = ON").await?;
                    }
                    Ok(())
                })
            })
            .acquire_timeout(Duration::from_secs(30))
            .connect(url)
            .await
            .map_err(|e| anyhow::anyhow!("cannot open the database {shown}: {e}"))?;
        migrator(backend)
            .run(&pool)
            .await
            .map_err(|e| anyhow::anyhow!("cannot migrate the database {shown}: {e}"))?;
        Ok(SqlStore { pool, backend })
    }
}

/// A migration's version, description and SQL.
type EmbeddedMigration = (i64, &'static str, &'static str);

/// Each backend's migrations, embedded in the binary: version, description and SQL
/// of each file of `migrations/sqlite` and `migrations/postgres` (a test checks them
/// against what sqlx reads from the folders). Listed by hand rather than by sqlx's
/// `migrate!`, whose macros would build sqlx's drivers, SQLite's C source among
/// them, a second time for the compiler.
fn migrations(backend: Backend) -> &'static [EmbeddedMigration] {
    match backend {
        Backend::Sqlite => &[(
            1,
            "jobs",
            include_str!("../../migrations/sqlite/0001_jobs.sql"),
        )],
        Backend::Postgres => &[(
            1,
            "jobs",
            include_str!("../../migrations/postgres/0001_jobs.sql"),
        )],
    }
}

/// The migrator of `backend`'s schema. The checksums are the SQL's own, as
/// `migrate!` made them, so databases made before keep their history.
fn migrator(backend: Backend) -> Migrator {
    Migrator::with_migrations(
        migrations(backend)
            .iter()
            .map(|&(version, description, sql)| {
                Migration::new(
                    version,
                    description.into(),
                    MigrationType::Simple,
                    SqlStr::from_static(sql),
                    sql.starts_with("-- no-transaction"),
                )
            })
            .collect(),
    )
}

/// A database URL without its password.
fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(a), Some(b)) if b > a => match url[a + 3..b].split_once(':') {
            Some((user, _)) => format!("{}{user}:***{}", &url[..a + 3], &url[b..]),
            None => url.to_string(),
        },
        _ => url.to_string(),
    }
}

const JOB_COLUMNS: &str = "id, owner, state, options, clip_key, clip_name, clip_bytes, clip_info, \
    idempotency_key, rerun_of, attempts, cancel_requested, frames_done, frames_total, fps, \
    error_code, error_message, artifacts, created_at, started_at, finished_at, updated_at, version";

/// A query whose text splices in [`JOB_COLUMNS`] (a constant; values are bound).
fn with_columns(sql: String) -> sqlx::query::Query<'static, sqlx::Any, sqlx::any::AnyArguments> {
    sqlx::query(sqlx::AssertSqlSafe(sql))
}

fn decode_err(what: &str, e: impl std::fmt::Display) -> sqlx::Error {
    sqlx::Error::Decode(format!("{what}: {e}").into())
}

fn job_from_row(row: &AnyRow) -> StoreResult<Job> {
    let state: String = row.try_get("state")?;
    let options: String = row.try_get("options")?;
    let clip_info: String = row.try_get("clip_info")?;
    let artifacts: String = row.try_get("artifacts")?;
    let error_code: Option<String> = row.try_get("error_code")?;
    let error_message: Option<String> = row.try_get("error_message")?;
    Ok(Job {
        id: row.try_get("id")?,
        owner: row.try_get("owner")?,
        state: JobState::parse(&state).ok_or_else(|| decode_err("job state", &state))?,
        options: serde_json::from_str(&options).map_err(|e| decode_err("job options", e))?,
        clip_key: row.try_get("clip_key")?,
        clip_name: row.try_get("clip_name")?,
        clip_bytes: row.try_get::<i64, _>("clip_bytes")? as u64,
        clip_info: serde_json::from_str(&clip_info).map_err(|e| decode_err("clip info", e))?,
        idempotency_key: row.try_get("idempotency_key")?,
        rerun_of: row.try_get("rerun_of")?,
        attempts: row.try_get::<i64, _>("attempts")? as u32,
        cancel_requested: row.try_get::<i64, _>("cancel_requested")? != 0,
        frames_done: row.try_get::<i64, _>("frames_done")? as u64,
        frames_total: row
            .try_get::<Option<i64>, _>("frames_total")?
            .map(|v| v as u64),
        fps: row.try_get("fps")?,
        error: error_code.map(|code| JobError {
            code,
            message: error_message.unwrap_or_default(),
        }),
        artifacts: serde_json::from_str::<Vec<Artifact>>(&artifacts)
            .map_err(|e| decode_err("artifacts", e))?,
        created_at: row.try_get("created_at")?,
        started_at: row.try_get("started_at")?,
        finished_at: row.try_get("finished_at")?,
        updated_at: row.try_get("updated_at")?,
        version: row.try_get("version")?,
    })
}

fn event_from_row(row: &AnyRow) -> StoreResult<Event> {
    let data: String = row.try_get("data")?;
    Ok(Event {
        seq: row.try_get("seq")?,
        kind: row.try_get("kind")?,
        data: serde_json::from_str(&data).map_err(|e| decode_err("event data", e))?,
    })
}

impl SqlStore {
    async fn job_by_id(&self, id: &str) -> StoreResult<Option<Job>> {
        let row = with_columns(format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(job_from_row).transpose()
    }

    async fn job_by_idempotency(&self, owner: &str, key: &str) -> StoreResult<Option<Job>> {
        let row = with_columns(format!(
            "SELECT {JOB_COLUMNS} FROM jobs WHERE owner = $1 AND idempotency_key = $2"
        ))
        .bind(owner)
        .bind(key)
        .fetch_optional(&self.pool)
        .await?;
        row.as_ref().map(job_from_row).transpose()
    }

    async fn insert_events(
        tx: &mut sqlx::AnyConnection,
        id: &str,
        events: &[Event],
    ) -> StoreResult<()> {
        for e in events {
            sqlx::query(
                "INSERT INTO job_events (job_id, seq, kind, data) VALUES ($1, $2, $3, $4) \
                 ON CONFLICT DO NOTHING",
            )
            .bind(id)
            .bind(e.seq)
            .bind(&e.kind)
            .bind(e.data.to_string())
            .execute(&mut *tx)
            .await?;
        }
        Ok(())
    }
}

impl Store for SqlStore {
    fn insert_job(&self, job: NewJob) -> BoxFuture<'_, StoreResult<Inserted>> {
        Box::pin(async move {
            if let Some(key) = &job.idempotency_key {
                if let Some(existing) = self.job_by_idempotency(&job.owner, key).await? {
                    return Ok(Inserted::Existing(existing));
                }
            }
            let now = now_ms();
            let mut tx = self.pool.begin().await?;
            let res = sqlx::query(
                "INSERT INTO jobs (id, owner, state, options, clip_key, clip_name, clip_bytes, \
                 clip_info, idempotency_key, rerun_of, created_at, updated_at) \
                 VALUES ($1, $2, 'queued', $3, $4, $5, $6, $7, $8, $9, $10, $10)",
            )
            .bind(&job.id)
            .bind(&job.owner)
            .bind(job.options.to_string())
            .bind(&job.clip_key)
            .bind(&job.clip_name)
            .bind(job.clip_bytes as i64)
            .bind(job.clip_info.to_string())
            .bind(&job.idempotency_key)
            .bind(&job.rerun_of)
            .bind(now)
            .execute(&mut *tx)
            .await;
            match res {
                Ok(_) => {}
                // Two uploads with the same key at once: the other one won.
                Err(sqlx::Error::Database(e)) if e.is_unique_violation() => {
                    tx.rollback().await?;
                    if let Some(key) = &job.idempotency_key {
                        if let Some(existing) = self.job_by_idempotency(&job.owner, key).await? {
                            return Ok(Inserted::Existing(existing));
                        }
                    }
                    return Err(sqlx::Error::Database(e));
                }
                Err(e) => return Err(e),
            }
            // Event 1, stored with the job: nothing else can number it.
            let first = Event {
                seq: 1,
                kind: "state".into(),
                data: serde_json::json!({ "state": "queued" }),
            };
            Self::insert_events(&mut tx, &job.id, &[first]).await?;
            tx.commit().await?;
            let inserted = self
                .job_by_id(&job.id)
                .await?
                .ok_or(sqlx::Error::RowNotFound)?;
            Ok(Inserted::New(inserted))
        })
    }

    fn job(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<Job>>> {
        let id = id.to_string();
        Box::pin(async move { self.job_by_id(&id).await })
    }

    fn list_jobs(&self, f: JobFilter) -> BoxFuture<'_, StoreResult<Vec<Job>>> {
        Box::pin(async move {
            let rows = with_columns(format!(
                "SELECT {JOB_COLUMNS} FROM jobs \
                 WHERE ($1 IS NULL OR owner = $1) AND ($2 IS NULL OR state = $2) \
                 AND ($3 IS NULL OR id < $3) AND ($5 IS NULL OR idempotency_key = $5) \
                 ORDER BY id DESC LIMIT $4"
            ))
            .bind(&f.owner)
            .bind(f.state.map(JobState::as_str))
            .bind(&f.before)
            .bind(f.limit as i64)
            .bind(&f.idempotency_key)
            .fetch_all(&self.pool)
            .await?;
            rows.iter().map(job_from_row).collect()
        })
    }

    fn queue_position(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<u64>>> {
        let id = id.to_string();
        Box::pin(async move {
            let row = sqlx::query(
                "SELECT CASE WHEN j.state = 'queued' THEN \
                 (SELECT COUNT(*) FROM jobs q WHERE q.state = 'queued' AND q.id < j.id) END AS pos \
                 FROM jobs j WHERE j.id = $1",
            )
            .bind(&id)
            .fetch_optional(&self.pool)
            .await?;
            Ok(match row {
                Some(r) => r.try_get::<Option<i64>, _>("pos")?.map(|v| v as u64),
                None => None,
            })
        })
    }

    fn count_by_state(&self) -> BoxFuture<'_, StoreResult<Vec<(JobState, u64)>>> {
        Box::pin(async move {
            let rows = sqlx::query("SELECT state, COUNT(*) AS n FROM jobs GROUP BY state")
                .fetch_all(&self.pool)
                .await?;
            let mut out: Vec<(JobState, u64)> = JobState::ALL.iter().map(|&s| (s, 0)).collect();
            for r in rows {
                let s: String = r.try_get("state")?;
                let n: i64 = r.try_get("n")?;
                if let Some(slot) = out.iter_mut().find(|(st, _)| st.as_str() == s) {
                    slot.1 = n as u64;
                }
            }
            Ok(out)
        })
    }

    fn claim_next(&self) -> BoxFuture<'_, StoreResult<Option<Job>>> {
        Box::pin(async move {
            let now = now_ms();
            let row = with_columns(format!(
                "UPDATE jobs SET state = 'running', attempts = attempts + 1, started_at = $1, \
                 updated_at = $1, version = version + 1, frames_done = 0 \
                 WHERE state = 'queued' \
                 AND id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY id LIMIT 1) \
                 RETURNING {JOB_COLUMNS}"
            ))
            .bind(now)
            .fetch_optional(&self.pool)
            .await?;
            row.as_ref().map(job_from_row).transpose()
        })
    }

    fn set_progress(&self, id: &str, p: ProgressRow) -> BoxFuture<'_, StoreResult<()>> {
        let id = id.to_string();
        Box::pin(async move {
            sqlx::query(
                "UPDATE jobs SET frames_done = $2, frames_total = $3, fps = $4, \
                 updated_at = $5, version = version + 1 WHERE id = $1 AND state = 'running'",
            )
            .bind(&id)
            .bind(p.frames_done as i64)
            .bind(p.frames_total.map(|v| v as i64))
            .bind(p.fps)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
            Ok(())
        })
    }

    fn append_events(&self, id: &str, events: Vec<Event>) -> BoxFuture<'_, StoreResult<()>> {
        let id = id.to_string();
        Box::pin(async move {
            let mut tx = self.pool.begin().await?;
            Self::insert_events(&mut tx, &id, &events).await?;
            tx.commit().await
        })
    }

    fn events_after(
        &self,
        id: &str,
        after: i64,
        limit: u32,
    ) -> BoxFuture<'_, StoreResult<Vec<Event>>> {
        let id = id.to_string();
        Box::pin(async move {
            let rows = sqlx::query(
                "SELECT seq, kind, data FROM job_events WHERE job_id = $1 AND seq > $2 \
                 ORDER BY seq LIMIT $3",
            )
            .bind(&id)
            .bind(after)
            .bind(limit as i64)
            .fetch_all(&self.pool)
            .await?;
            rows.iter().map(event_from_row).collect()
        })
    }

    fn last_event_seq(&self, id: &str) -> BoxFuture<'_, StoreResult<i64>> {
        let id = id.to_string();
        Box::pin(async move {
            let row = sqlx::query("SELECT MAX(seq) AS s FROM job_events WHERE job_id = $1")
                .bind(&id)
                .fetch_one(&self.pool)
                .await?;
            Ok(row.try_get::<Option<i64>, _>("s")?.unwrap_or(0))
        })
    }

    fn finish(
        &self,
        id: &str,
        from: &[JobState],
        outcome: Outcome,
        events: Vec<Event>,
    ) -> BoxFuture<'_, StoreResult<bool>> {
        let id = id.to_string();
        // One or two states (bound twice when one).
        let from_a = from.first().map_or("", |s| s.as_str());
        let from_b = from.get(1).map_or(from_a, |s| s.as_str());
        Box::pin(async move {
            let artifacts = serde_json::to_string(&outcome.artifacts)
                .map_err(|e| decode_err("artifacts", e))?;
            let mut tx = self.pool.begin().await?;
            let now = now_ms();
            let done = sqlx::query(
                "UPDATE jobs SET state = $2, error_code = $3, error_message = $4, artifacts = $5, \
                 finished_at = $6, updated_at = $6, version = version + 1 \
                 WHERE id = $1 AND state IN ($7, $8)",
            )
            .bind(&id)
            .bind(outcome.state.as_str())
            .bind(outcome.error.as_ref().map(|e| e.code.clone()))
            .bind(outcome.error.as_ref().map(|e| e.message.clone()))
            .bind(artifacts)
            .bind(now)
            .bind(from_a)
            .bind(from_b)
            .execute(&mut *tx)
            .await?
            .rows_affected()
                == 1;
            if done {
                Self::insert_events(&mut tx, &id, &events).await?;
            }
            tx.commit().await?;
            Ok(done)
        })
    }

    fn requeue(&self, id: &str) -> BoxFuture<'_, StoreResult<()>> {
        let id = id.to_string();
        Box::pin(async move {
            sqlx::query(
                "UPDATE jobs SET state = 'queued', attempts = CASE WHEN attempts > 0 THEN attempts - 1 ELSE 0 END, \
                 frames_done = 0, started_at = NULL, updated_at = $2, version = version + 1 \
                 WHERE id = $1 AND state = 'running'",
            )
            .bind(&id)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
            Ok(())
        })
    }

    fn request_cancel(&self, id: &str) -> BoxFuture<'_, StoreResult<()>> {
        let id = id.to_string();
        Box::pin(async move {
            sqlx::query(
                "UPDATE jobs SET cancel_requested = 1, updated_at = $2, version = version + 1 \
                 WHERE id = $1 AND cancel_requested = 0",
            )
            .bind(&id)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
            Ok(())
        })
    }

    fn delete_job(&self, id: &str) -> BoxFuture<'_, StoreResult<Option<Job>>> {
        let id = id.to_string();
        Box::pin(async move {
            let mut tx = self.pool.begin().await?;
            let row = with_columns(format!(
                "DELETE FROM jobs WHERE id = $1 RETURNING {JOB_COLUMNS}"
            ))
            .bind(&id)
            .fetch_optional(&mut *tx)
            .await?;
            sqlx::query("DELETE FROM job_events WHERE job_id = $1")
                .bind(&id)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
            row.as_ref().map(job_from_row).transpose()
        })
    }

    fn clip_users(&self, clip_key: &str) -> BoxFuture<'_, StoreResult<u64>> {
        let key = clip_key.to_string();
        Box::pin(async move {
            let row = sqlx::query("SELECT COUNT(*) AS n FROM jobs WHERE clip_key = $1")
                .bind(&key)
                .fetch_one(&self.pool)
                .await?;
            Ok(row.try_get::<i64, _>("n")? as u64)
        })
    }

    fn recover(&self, max_attempts: u32) -> BoxFuture<'_, StoreResult<Vec<Recovered>>> {
        Box::pin(async move {
            let now = now_ms();
            let mut tx = self.pool.begin().await?;
            let rows = sqlx::query(
                "UPDATE jobs SET \
                 state = CASE WHEN attempts >= $1 OR cancel_requested = 1 THEN \
                   (CASE WHEN cancel_requested = 1 THEN 'canceled' ELSE 'failed' END) \
                   ELSE 'queued' END, \
                 error_code = CASE WHEN cancel_requested = 1 THEN 'canceled' \
                   WHEN attempts >= $1 THEN 'gave_up' END, \
                 error_message = CASE WHEN cancel_requested = 1 THEN 'the job was canceled' \
                   WHEN attempts >= $1 THEN \
                   'the service stopped while tracking this clip ' || attempts || \
                   ' times; not trying again' END, \
                 finished_at = CASE WHEN attempts >= $1 OR cancel_requested = 1 THEN $2 END, \
                 frames_done = 0, updated_at = $2, version = version + 1 \
                 WHERE state = 'running' RETURNING id, state, attempts",
            )
            .bind(max_attempts as i64)
            .bind(now)
            .fetch_all(&mut *tx)
            .await?;
            tx.commit().await?;
            rows.iter()
                .map(|r| {
                    let state: String = r.try_get("state")?;
                    Ok(Recovered {
                        id: r.try_get("id")?,
                        state: JobState::parse(&state)
                            .ok_or_else(|| decode_err("job state", &state))?,
                        attempts: r.try_get::<i64, _>("attempts")? as u32,
                    })
                })
                .collect()
        })
    }

    fn create_key(
        &self,
        id: &str,
        name: &str,
        token_hash: &str,
    ) -> BoxFuture<'_, StoreResult<ApiKey>> {
        let (id, name, hash) = (id.to_string(), name.to_string(), token_hash.to_string());
        Box::pin(async move {
            let now = now_ms();
            sqlx::query(
                "INSERT INTO api_keys (id, name, token_hash, created_at) VALUES ($1, $2, $3, $4)",
            )
            .bind(&id)
            .bind(&name)
            .bind(&hash)
            .bind(now)
            .execute(&self.pool)
            .await?;
            Ok(ApiKey {
                id,
                name,
                created_at: now,
            })
        })
    }

    fn key_by_hash(&self, token_hash: &str) -> BoxFuture<'_, StoreResult<Option<ApiKey>>> {
        let hash = token_hash.to_string();
        Box::pin(async move {
            let row =
                sqlx::query("SELECT id, name, created_at FROM api_keys WHERE token_hash = $1")
                    .bind(&hash)
                    .fetch_optional(&self.pool)
                    .await?;
            row.map(|r| {
                Ok(ApiKey {
                    id: r.try_get("id")?,
                    name: r.try_get("name")?,
                    created_at: r.try_get("created_at")?,
                })
            })
            .transpose()
        })
    }

    fn count_keys(&self) -> BoxFuture<'_, StoreResult<u64>> {
        Box::pin(async move {
            let row = sqlx::query("SELECT COUNT(*) AS n FROM api_keys")
                .fetch_one(&self.pool)
                .await?;
            Ok(row.try_get::<i64, _>("n")? as u64)
        })
    }

    fn ping(&self) -> BoxFuture<'_, StoreResult<()>> {
        Box::pin(async move {
            sqlx::query("SELECT 1").execute(&self.pool).await?;
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The embedded list is what sqlx itself reads from each folder (the reading
    /// `migrate!` did): the same files, versions, descriptions, SQL and checksums.
    /// A file added to a folder but not to [`migrations`] would never run, and a
    /// checksum unlike `migrate!`'s would refuse every database made before.
    #[tokio::test]
    async fn the_embedded_migrations_are_what_sqlx_reads_from_the_folders() {
        for backend in [Backend::Sqlite, Backend::Postgres] {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(match backend {
                Backend::Sqlite => "migrations/sqlite",
                Backend::Postgres => "migrations/postgres",
            });
            let read = Migrator::new(dir.as_path()).await.expect("the migrations");
            let ours = migrator(backend);
            assert!(read.iter().count() > 0, "{backend:?}: no migrations read");
            assert_eq!(ours.iter().count(), read.iter().count(), "{backend:?}");
            for (a, b) in ours.iter().zip(read.iter()) {
                assert_eq!(a.version, b.version, "{backend:?}");
                assert_eq!(a.description, b.description, "{backend:?} {}", a.version);
                assert_eq!(a.migration_type, b.migration_type);
                assert_eq!(a.sql.as_str(), b.sql.as_str(), "{backend:?} {}", a.version);
                assert_eq!(a.checksum, b.checksum, "{backend:?} {}", a.version);
                assert_eq!(a.no_tx, b.no_tx);
            }
        }
    }
}
