//! The HTTP API (version 1): routes, access, errors, server-sent events. Every route
//! is described in `openapi.yaml` at the repository root (a test keeps the two in
//! step).

pub mod error;
pub mod events;
pub mod files;
pub mod jobs;
pub mod server;
pub mod upload;

use std::sync::Arc;
use std::time::Instant;

use axum::extract::{DefaultBodyLimit, FromRequestParts, MatchedPath, Request, State};
use axum::http::request::Parts;
use axum::http::StatusCode;
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use metrics_exporter_prometheus::PrometheusHandle;
use sha2::{Digest, Sha256};

use crate::jobs::worker::Jobs;
use error::{ApiError, ApiResult};

/// Limits of the API.
#[derive(Clone, Debug)]
pub struct ApiConfig {
    /// Largest upload in bytes (413 beyond).
    pub max_upload_bytes: u64,
    /// Most queued jobs (429 beyond).
    pub max_queue: u64,
    /// Where uploads are written while they arrive.
    pub upload_dir: std::path::PathBuf,
}

/// What every handler shares.
#[derive(Clone)]
pub struct AppState {
    pub jobs: Arc<Jobs>,
    pub cfg: Arc<ApiConfig>,
    pub metrics: Option<PrometheusHandle>,
}

/// The routes, as `openapi.yaml` lists them (method, path).
pub const ROUTES: [(&str, &str); 12] = [
    ("post", "/v1/jobs"),
    ("get", "/v1/jobs"),
    ("get", "/v1/jobs/{id}"),
    ("delete", "/v1/jobs/{id}"),
    ("get", "/v1/jobs/{id}/events"),
    ("get", "/v1/jobs/{id}/artifacts/{name}"),
    ("post", "/v1/jobs/{id}/cancel"),
    ("post", "/v1/jobs/{id}/rerun"),
    ("post", "/v1/probe"),
    ("get", "/healthz"),
    ("get", "/readyz"),
    ("get", "/metrics"),
];

pub fn router(state: AppState) -> Router {
    Router::new()
        .route("/v1/jobs", post(jobs::create).get(jobs::list))
        .route("/v1/jobs/{id}", get(jobs::show).delete(jobs::delete))
        .route("/v1/jobs/{id}/events", get(events::stream))
        .route("/v1/jobs/{id}/artifacts/{name}", get(files::artifact))
        .route("/v1/jobs/{id}/cancel", post(jobs::cancel))
        // Options only: a small body (jobs::MAX_RERUN_BYTES).
        .route("/v1/jobs/{id}/rerun", post(jobs::rerun))
        .route("/v1/probe", post(jobs::probe))
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics_text))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        // Uploads are capped by `max_upload_bytes` as they stream (see upload.rs).
        .layer(DefaultBodyLimit::disable())
        .layer(middleware::from_fn(track_requests))
        .layer(
            // A span per request (method, path), its answer logged with status and time.
            tower_http::trace::TraceLayer::new_for_http()
                .make_span_with(
                    tower_http::trace::DefaultMakeSpan::new().level(tracing::Level::INFO),
                )
                .on_response(
                    tower_http::trace::DefaultOnResponse::new().level(tracing::Level::INFO),
                ),
        )
        .with_state(state)
}

async fn not_found() -> ApiError {
    ApiError::not_found("no such route; see openapi.yaml for the API")
}

async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "this route does not take that method; see openapi.yaml",
    )
}

/// Request latency by route and status, for `/metrics`.
async fn track_requests(req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".into());
    let method = req.method().to_string();
    let start = Instant::now();
    let res = next.run(req).await;
    metrics::histogram!(
        "monocap_http_request_duration_seconds",
        "route" => route,
        "method" => method,
        "status" => res.status().as_u16().to_string()
    )
    .record(start.elapsed().as_secs_f64());
    res
}

async fn healthz() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "status": "ok" }))
}

async fn readyz(State(s): State<AppState>) -> Response {
    if s.jobs.shutdown.is_cancelled() {
        return ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "shutting_down",
            "the service is shutting down",
        )
        .into_response();
    }
    match s.jobs.store.ping().await {
        Ok(()) => Json(serde_json::json!({ "status": "ready" })).into_response(),
        Err(e) => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "database_unavailable",
            format!("the database does not answer: {e}"),
        )
        .into_response(),
    }
}

async fn metrics_text(State(s): State<AppState>) -> ApiResult<Response> {
    let Some(handle) = &s.metrics else {
        return Err(ApiError::not_found("metrics are off in this process"));
    };
    for (state, n) in s.jobs.store.count_by_state().await? {
        metrics::gauge!("monocap_jobs", "state" => state.as_str()).set(n as f64);
        if state == crate::store::JobState::Queued {
            metrics::gauge!("monocap_queue_depth").set(n as f64);
        }
    }
    metrics::gauge!("monocap_workers").set(s.jobs.cfg.workers as f64);
    Ok((
        [("content-type", "text/plain; version=0.0.4")],
        handle.render(),
    )
        .into_response())
}

/// Who is calling: the id of their API key, or `""` when the server has no keys
/// (then it only listens on a loopback address).
pub struct Caller(pub String);

/// SHA-256 of a token, hex (only this is stored).
pub fn token_hash(token: &str) -> String {
    Sha256::digest(token.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, s: &AppState) -> Result<Caller, ApiError> {
        let header = parts.headers.get("authorization");
        if s.jobs.store.count_keys().await? == 0 {
            return Ok(Caller(String::new()));
        }
        let unauthorized = |m: &str| ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", m);
        let Some(h) = header else {
            return Err(unauthorized(
                "send an API key as `Authorization: Bearer <token>` (create one with `monocap keys create`)",
            ));
        };
        let token = h
            .to_str()
            .ok()
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(str::trim)
            .ok_or_else(|| unauthorized("the Authorization header must be `Bearer <token>`"))?;
        match s.jobs.store.key_by_hash(&token_hash(token)).await? {
            Some(k) => Ok(Caller(k.id)),
            None => Err(unauthorized("unknown API key")),
        }
    }
}
