//! Job routes: submit, list, show (with ETags), cancel, delete, rerun, and probing a
//! clip without a job.

use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde_json::{json, Value};

use super::error::{ApiError, ApiPath, ApiResult};
use super::upload::{self, Upload};
use super::{AppState, Caller};
use crate::jobs::options::JobOptions;
use crate::store::{Inserted, Job, JobFilter, JobState, NewJob};

/// Largest body of a rerun (its options).
pub const MAX_RERUN_BYTES: usize = 256 << 10;

/// Longest idempotency key.
const MAX_IDEMPOTENCY_KEY: usize = 200;

fn rfc3339(ms: i64) -> Value {
    chrono::DateTime::from_timestamp_millis(ms)
        .map(|t| Value::String(t.to_rfc3339_opts(chrono::SecondsFormat::Millis, true)))
        .unwrap_or(Value::Null)
}

/// A job as the API shows it.
pub fn view(job: &Job, queue_position: Option<u64>) -> Value {
    let total = job.frames_total;
    let percent = total
        .filter(|&t| t > 0)
        .map(|t| (100.0 * job.frames_done as f64 / t as f64).min(100.0));
    let eta = match (total, job.fps, job.state) {
        (Some(t), Some(fps), JobState::Running) if fps > 0.0 => {
            Some(t.saturating_sub(job.frames_done) as f64 / fps)
        }
        _ => None,
    };
    let base = format!("/v1/jobs/{}", job.id);
    json!({
        "id": job.id,
        "state": job.state,
        "queue_position": queue_position,
        "attempts": job.attempts,
        "progress": {
            "frames_done": job.frames_done,
            "frames_total": total,
            "percent": percent,
            "fps": job.fps,
            "eta_s": eta,
        },
        "created_at": rfc3339(job.created_at),
        "started_at": job.started_at.map(rfc3339),
        "finished_at": job.finished_at.map(rfc3339),
        "options": job.options,
        "clip": { "name": job.clip_name, "bytes": job.clip_bytes, "info": job.clip_info },
        "error": job.error,
        "cancel_requested": job.cancel_requested,
        "rerun_of": job.rerun_of,
        "artifacts": job.artifacts.iter().map(|a| json!({
            "name": a.name,
            "bytes": a.bytes,
            "content_type": a.content_type,
            "url": format!("{base}/artifacts/{}", a.name),
        })).collect::<Vec<_>>(),
        "links": {
            "self": base,
            "events": format!("{base}/events"),
            "cancel": format!("{base}/cancel"),
            "rerun": format!("{base}/rerun"),
        },
    })
}

/// The job if it exists and belongs to the caller (others' jobs do not exist).
pub async fn owned(s: &AppState, caller: &Caller, id: &str) -> ApiResult<Job> {
    if uuid::Uuid::parse_str(id).is_err() {
        return Err(ApiError::not_found(format!(
            "no job {id:?} (job ids are UUIDs)"
        )));
    }
    match s.jobs.store.job(id).await? {
        Some(j) if j.owner == caller.0 => Ok(j),
        _ => Err(ApiError::not_found(format!("no job {id}"))),
    }
}

fn etag(job: &Job, pos: Option<u64>) -> String {
    format!(
        "\"{}-{}-{}\"",
        job.id,
        job.version,
        pos.map_or(-1, |p| p as i64)
    )
}

/// Whether `If-None-Match` names `tag` (or `*`).
pub(super) fn if_none_match(headers: &HeaderMap, tag: &str) -> bool {
    headers
        .get("if-none-match")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == tag || t.trim() == "*"))
}

/// `202 Accepted` with the job and its `Location`.
fn accepted(job: &Job, pos: Option<u64>) -> Response {
    let mut res = (StatusCode::ACCEPTED, Json(view(job, pos))).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/jobs/{}", job.id)) {
        res.headers_mut().insert("location", v);
    }
    res
}

fn idempotency_key(headers: &HeaderMap) -> ApiResult<Option<String>> {
    let Some(v) = headers.get("idempotency-key") else {
        return Ok(None);
    };
    let v = v
        .to_str()
        .ok()
        .filter(|v| !v.is_empty() && v.len() <= MAX_IDEMPOTENCY_KEY)
        .ok_or_else(|| {
            ApiError::bad_request(
                "bad_idempotency_key",
                format!(
                    "Idempotency-Key must be 1 to {MAX_IDEMPOTENCY_KEY} visible ASCII characters"
                ),
            )
        })?;
    Ok(Some(v.to_string()))
}

/// Refuses new work when the queue is full.
async fn check_queue(s: &AppState) -> ApiResult<()> {
    if s.jobs.shutdown.is_cancelled() {
        let mut e = ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "shutting_down",
            "the service is shutting down; try again shortly",
        );
        e.retry_after = Some(10);
        return Err(e);
    }
    let queued = s
        .jobs
        .store
        .count_by_state()
        .await?
        .into_iter()
        .find(|(st, _)| *st == JobState::Queued)
        .map_or(0, |(_, n)| n);
    if queued >= s.cfg.max_queue {
        let mut e = ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            "queue_full",
            format!("{queued} jobs are waiting, the most this service queues; try again later"),
        );
        e.retry_after = Some(30);
        return Err(e);
    }
    Ok(())
}

/// Checks options against the clip they are for.
fn check_options(opts: &JobOptions, info: &crate::clip::ClipInfo) -> ApiResult<()> {
    let track = opts
        .to_track()
        .map_err(|e| ApiError::unprocessable("bad_options", e))?;
    let n = info.frame_count as usize;
    if n == 0 {
        return Ok(());
    }
    let bad = |m: String| Err(ApiError::unprocessable("bad_options", m));
    if let Some((a, _)) = track.frames {
        if a >= n {
            return bad(format!("frames start at {a} but the clip has {n} frames"));
        }
    }
    if let Some(f) = track.track.init_frame {
        if f >= n {
            return bad(format!("init_frame {f} but the clip has {n} frames"));
        }
    }
    if let crate::vision::background::EmptyFrames::Range(_, b) = track.silhouettes.background.empty
    {
        if b > n {
            return bad(format!(
                "empty_frames end at {b} but the clip has {n} frames"
            ));
        }
    }
    track
        .track
        .keyframes
        .check_frames(n)
        .or_else(|e| bad(format!("keyframes: {e}")))
}

fn query_pairs(q: Option<&str>) -> Vec<(String, String)> {
    url_pairs(q.unwrap_or(""))
}

/// `a=1&b=x` decoded (percent-encoding and `+`).
fn url_pairs(q: &str) -> Vec<(String, String)> {
    serde_urlencoded::from_str::<Vec<(String, String)>>(q).unwrap_or_default()
}

/// `POST /v1/jobs`
pub async fn create(
    State(s): State<AppState>,
    caller: Caller,
    req: Request,
) -> ApiResult<Response> {
    let key = idempotency_key(req.headers())?;
    if let Some(k) = &key {
        if let Some(job) = find_idempotent(&s, &caller, k).await? {
            let pos = s.jobs.store.queue_position(&job.id).await?;
            return Ok(accepted(&job, pos));
        }
    }
    check_queue(&s).await?;
    let query = query_pairs(req.uri().query());
    let is_multipart = req
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.to_ascii_lowercase().starts_with("multipart/form-data"));
    if is_multipart && !query.is_empty() {
        return Err(ApiError::unprocessable(
            "bad_options",
            "with multipart/form-data, send options as the `options` part, not in the query",
        ));
    }
    let up = upload::receive(&s, req).await?;
    let opts = match &up.options {
        Some(v) => JobOptions::from_json(v.clone()),
        None => JobOptions::from_query(&query),
    }
    .map_err(|e| ApiError::unprocessable("bad_options", e))?;
    let info = upload::probe(&s, &up).await?;
    check_options(&opts, &info)?;
    let job = submit(&s, &caller, up, opts, info, key).await?;
    let pos = s.jobs.store.queue_position(&job.id).await?;
    Ok(accepted(&job, pos))
}

async fn find_idempotent(s: &AppState, caller: &Caller, key: &str) -> ApiResult<Option<Job>> {
    // The store answers idempotent inserts itself; this early look saves receiving
    // the same upload twice.
    let jobs = s
        .jobs
        .store
        .list_jobs(JobFilter {
            owner: Some(caller.0.clone()),
            limit: 1,
            idempotency_key: Some(key.to_string()),
            ..JobFilter::default()
        })
        .await?;
    Ok(jobs.into_iter().next())
}

/// Stores the clip and queues its job.
async fn submit(
    s: &AppState,
    caller: &Caller,
    up: Upload,
    opts: JobOptions,
    info: crate::clip::ClipInfo,
    key: Option<String>,
) -> ApiResult<Job> {
    let id = uuid::Uuid::now_v7().to_string();
    let clip_key = format!("clips/{id}");
    s.jobs
        .blobs
        .put_file(&clip_key, &up.file.0)
        .await
        .map_err(ApiError::from)?;
    let new = NewJob {
        id: id.clone(),
        owner: caller.0.clone(),
        options: serde_json::to_value(&opts).map_err(ApiError::internal)?,
        clip_key: clip_key.clone(),
        clip_name: up.name.clone(),
        clip_bytes: up.bytes,
        clip_info: serde_json::to_value(&info).map_err(ApiError::internal)?,
        idempotency_key: key,
        rerun_of: None,
    };
    match s.jobs.store.insert_job(new).await {
        Ok(Inserted::New(job)) => {
            queued(s);
            Ok(job)
        }
        Ok(Inserted::Existing(job)) => {
            let _ = s.jobs.blobs.delete(&clip_key).await;
            Ok(job)
        }
        Err(e) => {
            let _ = s.jobs.blobs.delete(&clip_key).await;
            Err(e.into())
        }
    }
}

/// Wakes the pool for a new job (its `queued` event was stored with it).
fn queued(s: &AppState) {
    metrics::counter!("monocap_jobs_submitted_total").increment(1);
    s.jobs.wake();
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    state: Option<String>,
    limit: Option<u32>,
    cursor: Option<String>,
}

/// `GET /v1/jobs`: newest first, `?state=`, `?limit=` (1–100, default 20),
/// `?cursor=` (the `next_cursor` of the previous page).
pub async fn list(
    State(s): State<AppState>,
    caller: Caller,
    q: Result<Query<ListQuery>, axum::extract::rejection::QueryRejection>,
) -> ApiResult<Json<Value>> {
    let Query(q) = q.map_err(|e| ApiError::bad_request("bad_query", e.body_text()))?;
    let state = match &q.state {
        None => None,
        Some(v) => Some(JobState::parse(v).ok_or_else(|| {
            ApiError::bad_request(
                "bad_query",
                format!("state {v:?}: expected queued, running, succeeded, failed or canceled"),
            )
        })?),
    };
    let limit = q.limit.unwrap_or(20);
    if !(1..=100).contains(&limit) {
        return Err(ApiError::bad_request(
            "bad_query",
            format!("limit {limit}: expected 1 to 100"),
        ));
    }
    if let Some(c) = &q.cursor {
        if uuid::Uuid::parse_str(c).is_err() {
            return Err(ApiError::bad_request(
                "bad_query",
                "cursor: use the next_cursor of the previous page",
            ));
        }
    }
    let jobs = s
        .jobs
        .store
        .list_jobs(JobFilter {
            owner: Some(caller.0.clone()),
            state,
            before: q.cursor.clone(),
            limit: limit + 1,
            idempotency_key: None,
        })
        .await?;
    let more = jobs.len() > limit as usize;
    let page = &jobs[..jobs.len().min(limit as usize)];
    let mut out = Vec::with_capacity(page.len());
    for j in page {
        let pos = if j.state == JobState::Queued {
            s.jobs.store.queue_position(&j.id).await?
        } else {
            None
        };
        out.push(view(j, pos));
    }
    Ok(Json(json!({
        "jobs": out,
        "next_cursor": if more { page.last().map(|j| j.id.clone()) } else { None },
    })))
}

/// `GET /v1/jobs/{id}` with `ETag`; `If-None-Match` answers `304`.
pub async fn show(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath(id): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    let job = owned(&s, &caller, &id).await?;
    let pos = s.jobs.store.queue_position(&job.id).await?;
    let tag = etag(&job, pos);
    let mut res = if if_none_match(&headers, &tag) {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        Json(view(&job, pos)).into_response()
    };
    if let Ok(v) = HeaderValue::from_str(&tag) {
        res.headers_mut().insert("etag", v);
    }
    res.headers_mut()
        .insert("cache-control", HeaderValue::from_static("no-cache"));
    Ok(res)
}

/// `POST /v1/jobs/{id}/cancel`
pub async fn cancel(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath(id): ApiPath<String>,
) -> ApiResult<Response> {
    let job = owned(&s, &caller, &id).await?;
    if !s.jobs.cancel(&job).await? {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "already_finished",
            format!("job {id} has already ended ({})", job.state.as_str()),
        ));
    }
    let job = owned(&s, &caller, &id).await?;
    Ok((StatusCode::ACCEPTED, Json(view(&job, None))).into_response())
}

/// `DELETE /v1/jobs/{id}`: the job, its events and files. A running job is canceled
/// first.
pub async fn delete(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath(id): ApiPath<String>,
) -> ApiResult<StatusCode> {
    let mut job = owned(&s, &caller, &id).await?;
    if !job.state.is_final() {
        s.jobs.cancel(&job).await?;
        let until = std::time::Instant::now() + std::time::Duration::from_secs(30);
        while !job.state.is_final() {
            if std::time::Instant::now() > until {
                return Err(ApiError::new(
                    StatusCode::CONFLICT,
                    "job_running",
                    "the job did not stop in time; try again",
                ));
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            job = owned(&s, &caller, &id).await?;
        }
    }
    let Some(gone) = s.jobs.store.delete_job(&id).await? else {
        return Err(ApiError::not_found(format!("no job {id}")));
    };
    s.jobs.bus.remove(&id);
    s.jobs.blobs.delete_prefix(&format!("jobs/{id}")).await?;
    if s.jobs.store.clip_users(&gone.clip_key).await? == 0 {
        s.jobs.blobs.delete(&gone.clip_key).await?;
    }
    Ok(StatusCode::NO_CONTENT)
}

/// `POST /v1/jobs/{id}/rerun`: a new job on the same clip; the body (optional JSON
/// options, such as new keyframes) replaces the old options field by field.
pub async fn rerun(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath(id): ApiPath<String>,
    body: axum::body::Body,
) -> ApiResult<Response> {
    // Read first: a refused body is drained, so that the client sees the answer.
    let body = super::upload::read_small(body, MAX_RERUN_BYTES, "the rerun options").await?;
    let old = owned(&s, &caller, &id).await?;
    check_queue(&s).await?;
    let old_opts: JobOptions = serde_json::from_value(old.options.clone())
        .map_err(|e| ApiError::internal(format!("stored options: {e}")))?;
    let opts = if body.iter().all(|b| b.is_ascii_whitespace()) {
        old_opts
    } else {
        let v: Value = serde_json::from_slice(&body).map_err(|e| {
            ApiError::unprocessable("bad_options", format!("options are not JSON: {e}"))
        })?;
        let new =
            JobOptions::from_json(v).map_err(|e| ApiError::unprocessable("bad_options", e))?;
        old_opts.merged(&new)
    };
    let info: crate::clip::ClipInfo = serde_json::from_value(old.clip_info.clone())
        .map_err(|e| ApiError::internal(format!("stored clip info: {e}")))?;
    check_options(&opts, &info)?;
    let new = NewJob {
        id: uuid::Uuid::now_v7().to_string(),
        owner: caller.0.clone(),
        options: serde_json::to_value(&opts).map_err(ApiError::internal)?,
        clip_key: old.clip_key.clone(),
        clip_name: old.clip_name.clone(),
        clip_bytes: old.clip_bytes,
        clip_info: old.clip_info.clone(),
        idempotency_key: None,
        rerun_of: Some(old.id.clone()),
    };
    let Inserted::New(job) = s.jobs.store.insert_job(new).await? else {
        return Err(ApiError::internal("a rerun matched an idempotency key"));
    };
    queued(&s);
    let pos = s.jobs.store.queue_position(&job.id).await?;
    Ok(accepted(&job, pos))
}

/// `POST /v1/probe`: what a clip is, without a job.
pub async fn probe(
    State(s): State<AppState>,
    _caller: Caller,
    req: Request,
) -> ApiResult<Json<Value>> {
    let up = upload::receive(&s, req).await?;
    let info = upload::probe(&s, &up).await?;
    Ok(Json(
        serde_json::to_value(&info).map_err(ApiError::internal)?,
    ))
}
