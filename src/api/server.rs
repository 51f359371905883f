//! `monocap serve`: settings (defaults, a TOML file, `MONOCAP_*` environment
//! variables and flags, later ones winning), start-up (database, files, recovery of
//! jobs the last process left running), the worker pool, and graceful shutdown on
//! SIGTERM or Ctrl-C (running jobs stop within a frame and go back to the queue).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::json;

use super::{router, ApiConfig, AppState};
use crate::jobs::worker::{Jobs, PoolConfig};
use crate::store::blobs::Blobs;
use crate::store::sql::SqlStore;
use crate::store::{JobState, Store};

/// The service's settings.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default)]
pub struct ServeConfig {
    /// Address and port to listen on.
    pub listen: String,
    /// Database and files.
    pub data_dir: PathBuf,
    /// A PostgreSQL database (`postgres://…`) instead of the data folder's SQLite
    /// file; files stay in the data folder.
    pub database_url: Option<String>,
    /// Jobs tracking at once (default and most: the machine's cores).
    pub workers: Option<usize>,
    /// Largest upload, MiB.
    pub max_upload_mb: u64,
    /// Most jobs waiting in the queue.
    pub max_queue: u64,
    /// Attempts before a job that keeps dying with the process is failed.
    pub max_attempts: u32,
    /// Longest a job may track, seconds (0: no limit).
    pub job_timeout_s: u64,
    /// Most frames a clip may have.
    pub max_frames: u64,
    /// Most pixels a frame may have.
    pub max_pixels: u64,
    /// Logs as JSON lines.
    pub log_json: bool,
}

impl Default for ServeConfig {
    fn default() -> Self {
        let limits = crate::clip::Limits::default();
        ServeConfig {
            listen: "127.0.0.1:8080".into(),
            data_dir: PathBuf::from("monocap-data"),
            database_url: None,
            workers: None,
            max_upload_mb: 2048,
            max_queue: 1000,
            max_attempts: 3,
            job_timeout_s: 6 * 3600,
            max_frames: limits.max_frames,
            max_pixels: limits.max_pixels,
            log_json: false,
        }
    }
}

impl ServeConfig {
    /// Defaults, then the TOML file, then `MONOCAP_*` variables, then `overrides`
    /// (the flags given).
    pub fn load(file: Option<&Path>, overrides: serde_json::Value) -> Result<ServeConfig> {
        use figment::providers::{Env, Format, Serialized, Toml};
        let mut fig = figment::Figment::from(Serialized::defaults(ServeConfig::default()));
        if let Some(f) = file {
            if !f.is_file() {
                anyhow::bail!("config file {} does not exist", f.display());
            }
            fig = fig.merge(Toml::file(f));
        }
        fig = fig
            .merge(Env::prefixed("MONOCAP_").only(&[
                "listen",
                "data_dir",
                "database_url",
                "workers",
                "max_upload_mb",
                "max_queue",
                "max_attempts",
                "job_timeout_s",
                "max_frames",
                "max_pixels",
                "log_json",
            ]))
            .merge(Serialized::defaults(overrides));
        fig.extract().map_err(|e| anyhow::anyhow!("settings: {e}"))
    }
}

/// Opens the database: `database_url`, or the data folder's SQLite file.
pub async fn open_store(data_dir: &Path, database_url: Option<&str>) -> Result<SqlStore> {
    std::fs::create_dir_all(data_dir)
        .with_context(|| format!("cannot create the data folder {}", data_dir.display()))?;
    match database_url {
        Some(url) => SqlStore::connect(url).await,
        None => SqlStore::open_sqlite(&data_dir.join("monocap.db")).await,
    }
}

/// `monocap keys create`: a new API key; returns (id, token).
pub async fn create_key(
    data_dir: &Path,
    database_url: Option<&str>,
    name: &str,
) -> Result<(String, String)> {
    let name = name.trim();
    if name.is_empty() || name.len() > 100 || name.chars().any(char::is_control) {
        anyhow::bail!("--name {name:?}: expected 1 to 100 printable characters");
    }
    let store = open_store(data_dir, database_url).await?;
    let secret: [u8; 32] = rand::random();
    let token = format!(
        "mck_{}",
        secret
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    );
    let id = uuid::Uuid::now_v7().to_string();
    store
        .create_key(&id, name, &super::token_hash(&token))
        .await?;
    Ok((id, token))
}

/// Runs the service until SIGTERM or Ctrl-C.
pub async fn serve(cfg: ServeConfig) -> Result<()> {
    let addr: SocketAddr = cfg
        .listen
        .parse()
        .with_context(|| format!("--listen {:?}: expected ADDRESS:PORT", cfg.listen))?;
    let store = open_store(&cfg.data_dir, cfg.database_url.as_deref()).await?;
    let keys = store.count_keys().await?;
    if keys == 0 && !addr.ip().is_loopback() {
        anyhow::bail!(
            "refusing to listen on {addr} without API keys: create one with `monocap keys create --name NAME --data-dir {}`, or listen on 127.0.0.1",
            cfg.data_dir.display()
        );
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let workers = cfg.workers.unwrap_or(cores).clamp(1, cores);
    let blobs = Blobs::local(&cfg.data_dir.join("blobs"))?;
    let upload_dir = cfg.data_dir.join("uploads");
    let work_dir = cfg.data_dir.join("work");
    // Half-received uploads and scratch files of the last process.
    for dir in [&upload_dir, &work_dir] {
        let _ = std::fs::remove_dir_all(dir);
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let limits = crate::clip::Limits {
        max_frames: cfg.max_frames,
        max_pixels: cfg.max_pixels,
        ..crate::clip::Limits::default()
    };
    let store: Arc<dyn Store> = Arc::new(store);
    let jobs = Arc::new(Jobs::new(
        store.clone(),
        blobs,
        PoolConfig {
            workers,
            max_attempts: cfg.max_attempts.max(1),
            job_timeout: (cfg.job_timeout_s > 0).then(|| Duration::from_secs(cfg.job_timeout_s)),
            limits,
            work_dir,
        },
    ));
    recover(&jobs).await?;

    let metrics = metrics_exporter_prometheus::PrometheusBuilder::new()
        .install_recorder()
        .ok();
    let state = AppState {
        jobs: jobs.clone(),
        cfg: Arc::new(ApiConfig {
            max_upload_bytes: cfg.max_upload_mb.saturating_mul(1 << 20),
            max_queue: cfg.max_queue,
            upload_dir,
        }),
        metrics,
    };
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .with_context(|| format!("cannot listen on {addr}"))?;
    let local = listener.local_addr()?;
    let access = if keys == 0 {
        "open: no API keys, loopback only".to_string()
    } else {
        format!("{keys} API key(s); requests need `Authorization: Bearer`")
    };
    tracing::info!(%local, workers, "listening");
    println!(
        "monocap: listening on http://{local} ({access}; {workers} worker(s); data in {})",
        cfg.data_dir.display()
    );
    let pool = tokio::spawn(jobs.clone().run());
    let stop = jobs.shutdown.clone();
    tokio::spawn(async move {
        shutdown_signal().await;
        tracing::info!("shutting down: running jobs go back to the queue");
        stop.cancel();
    });
    axum::serve(listener, router(state))
        .with_graceful_shutdown(jobs.shutdown.clone().cancelled_owned())
        .await?;
    pool.await?;
    println!("monocap: stopped");
    Ok(())
}

/// More events than a job can stream between two writes to the database.
const UNSTORED_EVENTS: i64 = 1_000_000;

/// Jobs the last process left running: back to the queue, or failed after too
/// many attempts.
async fn recover(jobs: &Jobs) -> Result<()> {
    for r in jobs.store.recover(jobs.cfg.max_attempts.max(1)).await? {
        tracing::warn!(job = %r.id, state = r.state.as_str(), attempts = r.attempts, "recovered a job left running");
        // The dead process may have streamed progress events it never stored (they
        // are written twice a second): number on past them, so that an id a client
        // saw is never given to another event (its Last-Event-ID would skip that one).
        let last = jobs.store.last_event_seq(&r.id).await?;
        jobs.bus.open(&r.id, last + 1 + UNSTORED_EVENTS);
        let events = match r.state {
            JobState::Queued => vec![(
                "state",
                json!({ "state": "queued", "reason": "the service stopped while tracking; trying again", "attempts": r.attempts }),
            )],
            s => {
                let job = jobs.store.job(&r.id).await?;
                let error = job.and_then(|j| j.error);
                vec![
                    ("state", json!({ "state": s.as_str() })),
                    ("failed", json!({ "state": s.as_str(), "error": error })),
                ]
            }
        };
        jobs.record(&r.id, events).await?;
        if r.state.is_final() {
            jobs.bus.remove(&r.id);
        }
    }
    Ok(())
}

async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        if let Ok(mut term) = signal(SignalKind::terminate()) {
            tokio::select! {
                _ = term.recv() => {}
                _ = tokio::signal::ctrl_c() => {}
            }
            return;
        }
    }
    let _ = tokio::signal::ctrl_c().await;
}
