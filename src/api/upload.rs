//! Receiving a clip: as `multipart/form-data` (part `clip`, optional part
//! `options`) or as the raw body. The bytes stream to a file under the upload folder,
//! never whole in memory, counted against the upload limit as they come; the file is
//! removed when the upload fails or is not kept. The clip is probed before anything
//! is accepted.

use std::path::{Path, PathBuf};
use std::time::Duration;

use axum::extract::{FromRequest, Multipart, Request};
use axum::http::StatusCode;
use futures_util::StreamExt;
use tokio::io::AsyncWriteExt;
use tokio::time::Instant;

use super::error::{ApiError, ApiResult};
use super::AppState;
use crate::clip::{ClipInfo, DecodeError};

/// Largest `options` part.
const MAX_OPTIONS_BYTES: usize = 256 << 10;

/// After refusing an upload as too large, the rest of its body is read and dropped
/// (up to this many bytes, for up to `DRAIN_TIME`, while it keeps coming) before
/// answering: a server that closes with unread data resets the connection, and the
/// client, still sending, then sees a broken pipe instead of the 413.
const DRAIN_MAX_BYTES: u64 = 64 << 20;
const DRAIN_TIME: Duration = Duration::from_secs(10);
/// Draining stops when nothing comes for this long.
const DRAIN_IDLE: Duration = Duration::from_secs(1);

/// When draining waits no longer for the next piece: at `until`, or after a pause
/// of [`DRAIN_IDLE`].
fn drain_deadline(until: Instant) -> Instant {
    until.min(Instant::now() + DRAIN_IDLE)
}

/// Reads and drops what is left of a refused upload (see [`DRAIN_MAX_BYTES`]).
async fn drain<S, B, E>(mut stream: S)
where
    S: futures_util::Stream<Item = Result<B, E>> + Unpin,
    B: AsRef<[u8]>,
{
    let until = Instant::now() + DRAIN_TIME;
    let mut n = 0u64;
    while let Ok(Some(Ok(chunk))) =
        tokio::time::timeout_at(drain_deadline(until), stream.next()).await
    {
        n += chunk.as_ref().len() as u64;
        if n > DRAIN_MAX_BYTES {
            break;
        }
    }
}

/// A small request body (options), read whole: at most `limit` bytes. A larger one is
/// refused with 413 after what is left of it is drained (see [`DRAIN_MAX_BYTES`]).
pub async fn read_small(body: axum::body::Body, limit: usize, what: &str) -> ApiResult<Vec<u8>> {
    let mut stream = body.into_data_stream();
    let mut out = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| {
            ApiError::bad_request("bad_request", format!("{what} ended early: {e}"))
        })?;
        if out.len() + chunk.len() > limit {
            drain(stream).await;
            return Err(ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "too_large",
                format!("{what} are larger than the limit of {limit} bytes"),
            ));
        }
        out.extend_from_slice(&chunk);
    }
    Ok(out)
}

/// [`drain`] for one part of a multipart body, counting into `n`; false when it
/// stopped before the end of the part.
async fn drain_field(
    field: &mut axum::extract::multipart::Field<'_>,
    n: &mut u64,
    until: Instant,
) -> bool {
    loop {
        match tokio::time::timeout_at(drain_deadline(until), field.chunk()).await {
            Ok(Ok(Some(c))) => {
                *n += c.len() as u64;
                if *n > DRAIN_MAX_BYTES {
                    return false;
                }
            }
            Ok(Ok(None)) => return true,
            _ => return false,
        }
    }
}

/// A file removed when dropped (unless kept).
pub struct TempFile(pub PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// A received clip.
pub struct Upload {
    pub file: TempFile,
    /// The file name the client gave (for messages), or `clip`.
    pub name: String,
    pub bytes: u64,
    /// The `options` part, when there was one.
    pub options: Option<serde_json::Value>,
}

/// Content types taken as a raw clip body.
fn is_clip_type(ct: &str) -> bool {
    ct.starts_with("video/")
        || matches!(
            ct,
            "image/gif"
                | "image/webp"
                | "image/apng"
                | "image/png"
                | "application/zip"
                | "application/x-zip-compressed"
                | "application/x-tar"
                | "application/octet-stream"
        )
}

fn too_large(limit: u64) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "too_large",
        format!("the upload is larger than the limit of {limit} bytes"),
    )
}

/// Receives the request's clip.
pub async fn receive(state: &AppState, req: Request) -> ApiResult<Upload> {
    let limit = state.cfg.max_upload_bytes;
    if let Some(len) = req
        .headers()
        .get("content-length")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok())
    {
        if len > limit + MAX_OPTIONS_BYTES as u64 + 64 * 1024 {
            if len <= DRAIN_MAX_BYTES {
                drain(req.into_body().into_data_stream()).await;
            }
            return Err(too_large(limit));
        }
    }
    let ct = req
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_ascii_lowercase();
    let essence = ct.split(';').next().unwrap_or("").trim().to_string();
    if essence == "multipart/form-data" {
        let mut mp = Multipart::from_request(req, state)
            .await
            .map_err(|e| ApiError::bad_request("bad_upload", e.body_text()))?;
        return receive_multipart(state, &mut mp).await;
    }
    if !is_clip_type(&essence) {
        let what = if essence.is_empty() {
            "no Content-Type".to_string()
        } else {
            format!("Content-Type {essence}")
        };
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media",
            format!(
                "{what}: send the clip as multipart/form-data (part `clip`) or as the raw \
                 body with a video/*, image/gif, image/webp, application/zip, application/x-tar \
                 or application/octet-stream type"
            ),
        ));
    }
    let file = new_temp(&state.cfg.upload_dir)?;
    let mut w = ChunkWriter::create(&file.0, limit).await?;
    let mut stream = req.into_body().into_data_stream();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| {
            ApiError::bad_request("bad_upload", format!("the upload ended early: {e}"))
        })?;
        if let Err(e) = w.push(&chunk).await {
            drain(stream).await;
            return Err(e);
        }
    }
    let bytes = w.finish().await?;
    Ok(Upload {
        file,
        name: "clip".into(),
        bytes,
        options: None,
    })
}

async fn receive_multipart(state: &AppState, mp: &mut Multipart) -> ApiResult<Upload> {
    let limit = state.cfg.max_upload_bytes;
    let mut clip: Option<(TempFile, String, u64)> = None;
    let mut options = None;
    let bad = |e: axum::extract::multipart::MultipartError| {
        ApiError::bad_request(
            "bad_upload",
            format!(
                "the multipart body is malformed or ends early: {}",
                e.body_text()
            ),
        )
    };
    while let Some(mut field) = mp.next_field().await.map_err(bad)? {
        match field.name().unwrap_or("") {
            "clip" => {
                if clip.is_some() {
                    return Err(ApiError::unprocessable(
                        "bad_upload",
                        "more than one `clip` part",
                    ));
                }
                let name = field
                    .file_name()
                    .map(sanitize_name)
                    .unwrap_or_else(|| "clip".into());
                let file = new_temp(&state.cfg.upload_dir)?;
                let mut w = ChunkWriter::create(&file.0, limit).await?;
                let mut refused = None;
                while let Some(chunk) = field.chunk().await.map_err(bad)? {
                    if let Err(e) = w.push(&chunk).await {
                        refused = Some(e);
                        break;
                    }
                }
                if let Some(e) = refused {
                    // Read the rest (see `drain`) so that the client gets the answer.
                    let until = Instant::now() + DRAIN_TIME;
                    let mut n = 0;
                    if drain_field(&mut field, &mut n, until).await {
                        drop(field);
                        while let Ok(Ok(Some(mut f))) =
                            tokio::time::timeout_at(drain_deadline(until), mp.next_field()).await
                        {
                            if !drain_field(&mut f, &mut n, until).await {
                                break;
                            }
                        }
                    }
                    return Err(e);
                }
                let bytes = w.finish().await?;
                clip = Some((file, name, bytes));
            }
            "options" => {
                let mut text = Vec::new();
                while let Some(chunk) = field.chunk().await.map_err(bad)? {
                    text.extend_from_slice(&chunk);
                    if text.len() > MAX_OPTIONS_BYTES {
                        return Err(ApiError::unprocessable(
                            "bad_options",
                            format!("the options part is larger than {MAX_OPTIONS_BYTES} bytes"),
                        ));
                    }
                }
                let v: serde_json::Value = serde_json::from_slice(&text).map_err(|e| {
                    ApiError::unprocessable("bad_options", format!("options are not JSON: {e}"))
                })?;
                options = Some(v);
            }
            other => {
                return Err(ApiError::unprocessable(
                    "bad_upload",
                    format!("unknown part {other:?}: expected `clip` and optionally `options`"),
                ))
            }
        }
    }
    let (file, name, bytes) = clip.ok_or_else(|| {
        ApiError::unprocessable("bad_upload", "the multipart body has no `clip` part")
    })?;
    Ok(Upload {
        file,
        name,
        bytes,
        options,
    })
}

/// Keeps the last path component of a client's file name, printable characters only.
fn sanitize_name(name: &str) -> String {
    let base = name.rsplit(['/', '\\']).next().unwrap_or("");
    let clean: String = base.chars().filter(|c| !c.is_control()).take(200).collect();
    if clean.is_empty() {
        "clip".into()
    } else {
        clean
    }
}

fn new_temp(dir: &Path) -> ApiResult<TempFile> {
    std::fs::create_dir_all(dir).map_err(ApiError::internal)?;
    Ok(TempFile(dir.join(format!("{}.part", uuid::Uuid::now_v7()))))
}

/// Writes chunks to a file, failing past `limit` bytes.
struct ChunkWriter {
    f: tokio::fs::File,
    total: u64,
    limit: u64,
}

impl ChunkWriter {
    async fn create(path: &Path, limit: u64) -> ApiResult<ChunkWriter> {
        let f = tokio::fs::File::create(path)
            .await
            .map_err(ApiError::internal)?;
        Ok(ChunkWriter { f, total: 0, limit })
    }

    async fn push(&mut self, chunk: &[u8]) -> ApiResult<()> {
        self.total += chunk.len() as u64;
        if self.total > self.limit {
            return Err(too_large(self.limit));
        }
        self.f.write_all(chunk).await.map_err(ApiError::internal)
    }

    async fn finish(mut self) -> ApiResult<u64> {
        self.f.flush().await.map_err(ApiError::internal)?;
        metrics::counter!("monocap_upload_bytes_total").increment(self.total);
        if self.total == 0 {
            return Err(ApiError::unprocessable(
                "empty_clip",
                "the clip is empty (0 bytes)",
            ));
        }
        Ok(self.total)
    }
}

/// Probes the received clip off the async runtime; errors name the client's file,
/// not the server's.
pub async fn probe(state: &AppState, up: &Upload) -> ApiResult<ClipInfo> {
    let path = up.file.0.clone();
    let limits = state.jobs.cfg.limits.clone();
    let res = tokio::task::spawn_blocking(move || crate::clip::open::probe(&path, &limits))
        .await
        .map_err(ApiError::internal)?;
    let shown = up.file.0.display().to_string();
    let msg = |e: &DecodeError| e.to_string().replace(&shown, &up.name);
    match res {
        Ok(info) => Ok(info),
        Err(e @ (DecodeError::UnknownFormat { .. } | DecodeError::UnsupportedCodec { .. })) => {
            Err(ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_media",
                msg(&e),
            ))
        }
        Err(e @ DecodeError::TooLarge { .. }) => {
            Err(ApiError::unprocessable("clip_too_large", msg(&e)))
        }
        Err(e @ DecodeError::Io { .. }) => Err(ApiError::internal(msg(&e))),
        Err(e) => Err(ApiError::unprocessable("unreadable_clip", msg(&e))),
    }
}
