//! `GET /v1/jobs/{id}/artifacts/{name}`: a finished job's files, with
//! `Content-Type`, `Content-Disposition`, a strong `ETag` (files never change once
//! made), `If-None-Match` and single byte ranges (`Range: bytes=a-b`, `a-`, `-n`).

use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;

use super::error::{ApiError, ApiPath, ApiResult};
use super::jobs::{if_none_match, owned};
use super::{AppState, Caller};
use crate::jobs::worker::artifact_key;

/// A range that cannot be served (answered with 416).
#[derive(Debug, PartialEq, Eq)]
pub struct Unsatisfiable;

/// A `Range` header resolved against the file's size: `Ok(None)` for the whole
/// file (no header, or one this server does not split, such as several ranges),
/// `Err` when it cannot be satisfied.
pub fn parse_range(header: Option<&str>, size: u64) -> Result<Option<(u64, u64)>, Unsatisfiable> {
    let Some(h) = header else { return Ok(None) };
    let Some(spec) = h.trim().strip_prefix("bytes=") else {
        return Ok(None);
    };
    if spec.contains(',') {
        return Ok(None);
    }
    let (a, b) = spec.split_once('-').ok_or(Unsatisfiable)?;
    let (a, b) = (a.trim(), b.trim());
    let range = if a.is_empty() {
        let n: u64 = b.parse().map_err(|_| Unsatisfiable)?;
        if n == 0 || size == 0 {
            return Err(Unsatisfiable);
        }
        (size.saturating_sub(n), size - 1)
    } else {
        let start: u64 = a.parse().map_err(|_| Unsatisfiable)?;
        let end = if b.is_empty() {
            size.saturating_sub(1)
        } else {
            b.parse::<u64>()
                .map_err(|_| Unsatisfiable)?
                .min(size.saturating_sub(1))
        };
        if start >= size || end < start {
            return Err(Unsatisfiable);
        }
        (start, end)
    };
    Ok(Some(range))
}

pub async fn artifact(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath((id, name)): ApiPath<(String, String)>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    let job = owned(&s, &caller, &id).await?;
    let Some(a) = job.artifacts.iter().find(|a| a.name == name) else {
        let msg = if job.state.is_final() {
            format!("job {id} has no file {name:?}")
        } else {
            format!(
                "job {id} is {}; its files come when it succeeds",
                job.state.as_str()
            )
        };
        return Err(ApiError::not_found(msg));
    };
    let tag = format!("\"{}-{}-{}\"", job.id, a.name, a.bytes);
    let mut h = HeaderMap::new();
    let hv = |v: &str| HeaderValue::from_str(v).map_err(ApiError::internal);
    h.insert("etag", hv(&tag)?);
    h.insert("accept-ranges", HeaderValue::from_static("bytes"));
    h.insert("content-type", hv(&a.content_type)?);
    h.insert(
        "content-disposition",
        hv(&format!("attachment; filename=\"{}\"", a.name))?,
    );
    if if_none_match(&headers, &tag) {
        return Ok((StatusCode::NOT_MODIFIED, h).into_response());
    }
    // A Range with a stale If-Range gets the whole file.
    let if_range_ok = headers
        .get("if-range")
        .and_then(|v| v.to_str().ok())
        .is_none_or(|v| v.trim() == tag);
    let range_header = headers.get("range").and_then(|v| v.to_str().ok());
    let range = match parse_range(range_header.filter(|_| if_range_ok), a.bytes) {
        Ok(r) => r,
        Err(Unsatisfiable) => {
            h.insert("content-range", hv(&format!("bytes */{}", a.bytes))?);
            // The body is the JSON error, not the file.
            h.remove("content-type");
            h.remove("content-disposition");
            let mut res = ApiError::new(
                StatusCode::RANGE_NOT_SATISFIABLE,
                "bad_range",
                format!("the file has {} bytes", a.bytes),
            )
            .into_response();
            res.headers_mut().extend(h);
            return Ok(res);
        }
    };
    let key = artifact_key(&job.id, &a.name);
    let got = s.jobs.blobs.get(&key, range.map(|(a, b)| a..b + 1)).await?;
    let body = Body::from_stream(got.into_stream().map(|r| r.map_err(std::io::Error::other)));
    let status = match range {
        Some((start, end)) => {
            h.insert(
                "content-range",
                hv(&format!("bytes {start}-{end}/{}", a.bytes))?,
            );
            h.insert("content-length", hv(&(end - start + 1).to_string())?);
            StatusCode::PARTIAL_CONTENT
        }
        None => {
            h.insert("content-length", hv(&a.bytes.to_string())?);
            StatusCode::OK
        }
    };
    Ok((status, h, body).into_response())
}

#[cfg(test)]
mod tests {
    use super::{parse_range, Unsatisfiable};

    #[test]
    fn ranges() {
        assert_eq!(parse_range(None, 10), Ok(None));
        assert_eq!(parse_range(Some("bytes=0-3"), 10), Ok(Some((0, 3))));
        assert_eq!(parse_range(Some("bytes=5-"), 10), Ok(Some((5, 9))));
        assert_eq!(parse_range(Some("bytes=-3"), 10), Ok(Some((7, 9))));
        assert_eq!(parse_range(Some("bytes=-30"), 10), Ok(Some((0, 9))));
        assert_eq!(parse_range(Some("bytes=8-100"), 10), Ok(Some((8, 9))));
        assert_eq!(parse_range(Some("bytes=0-1,4-5"), 10), Ok(None));
        assert_eq!(parse_range(Some("items=0-1"), 10), Ok(None));
        assert_eq!(parse_range(Some("bytes=10-"), 10), Err(Unsatisfiable));
        assert_eq!(parse_range(Some("bytes=4-2"), 10), Err(Unsatisfiable));
        assert_eq!(parse_range(Some("bytes=x-2"), 10), Err(Unsatisfiable));
        assert_eq!(parse_range(Some("bytes=-0"), 10), Err(Unsatisfiable));
    }
}
