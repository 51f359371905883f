//! `GET /v1/jobs/{id}/events`: server-sent events. First the job as it is now (an
//! event `state` without an id), then every stored event after `Last-Event-ID`
//! (database first, then the live log: nothing missed, nothing twice), then live
//! ones as they come, keep-alive comments between them, and the stream ends after
//! the final `done` or `failed`.

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use futures_util::Stream;
use tokio::sync::mpsc;

use super::error::{ApiError, ApiPath, ApiResult};
use super::jobs::{owned, view};
use super::{AppState, Caller};
use crate::store::Event;

/// Events read from the database per query.
const PAGE: u32 = 1000;

fn sse(e: &Event) -> SseEvent {
    SseEvent::default()
        .id(e.seq.to_string())
        .event(&e.kind)
        .data(e.data.to_string())
}

fn is_final(e: &Event) -> bool {
    e.kind == "done" || e.kind == "failed"
}

pub async fn stream(
    State(s): State<AppState>,
    caller: Caller,
    ApiPath(id): ApiPath<String>,
    headers: HeaderMap,
) -> ApiResult<Sse<impl Stream<Item = Result<SseEvent, Infallible>>>> {
    let job = owned(&s, &caller, &id).await?;
    let after = match headers.get("last-event-id") {
        None => 0,
        Some(v) => v
            .to_str()
            .ok()
            .and_then(|v| v.trim().parse::<i64>().ok())
            .filter(|&v| v >= 0)
            .ok_or_else(|| {
                ApiError::bad_request("bad_last_event_id", "Last-Event-ID must be an event id")
            })?,
    };
    let pos = s.jobs.store.queue_position(&id).await?;
    let first = SseEvent::default()
        .event("state")
        .data(view(&job, pos).to_string());
    let (tx, mut rx) = mpsc::channel::<SseEvent>(64);
    tokio::spawn(async move {
        if tx.send(first).await.is_err() {
            return;
        }
        if let Err(e) = pump(&s, &id, after, &tx).await {
            tracing::warn!(job = %id, "event stream ended early: {e:#}");
        }
    });
    let stream = futures_util::stream::poll_fn(move |cx| rx.poll_recv(cx).map(|o| o.map(Ok)));
    Ok(Sse::new(stream).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

/// Sends the job's events after `cursor` until the final one (or until the client
/// leaves or the service shuts down).
async fn pump(
    s: &super::AppState,
    id: &str,
    mut cursor: i64,
    tx: &mpsc::Sender<SseEvent>,
) -> anyhow::Result<()> {
    let send = |e: Event| async move { tx.send(sse(&e)).await.is_ok() };
    loop {
        // Taken first, so that a log opened or a job ended after the look below
        // wakes the wait for one.
        let mut changes = s.jobs.bus.changes();
        // Whatever is live now stays readable through this handle even if the job
        // ends meanwhile.
        let live = s.jobs.bus.get(id);
        let mut signal = live.as_ref().map(|l| l.subscribe());
        // The database: everything stored after the cursor.
        loop {
            let page = s.jobs.store.events_after(id, cursor, PAGE).await?;
            let n = page.len();
            for e in page {
                cursor = e.seq;
                let last = is_final(&e);
                if !send(e).await || last {
                    return Ok(());
                }
            }
            if n < PAGE as usize {
                break;
            }
        }
        let Some(live) = live else {
            // Not live in this process: ended (all stored, sent above), deleted, or
            // queued without a log yet (or run by another process); look again when
            // a log opens or a job ends here, or shortly.
            match s.jobs.store.job(id).await? {
                Some(j) if !j.state.is_final() => {}
                _ => return Ok(()),
            }
            tokio::select! {
                _ = changes.changed() => continue,
                _ = tokio::time::sleep(Duration::from_millis(500)) => continue,
                _ = s.jobs.shutdown.cancelled() => return Ok(()),
                _ = tx.closed() => return Ok(()),
            }
        };
        // The live log, as long as it lasts.
        loop {
            let (events, closed) = live.after(cursor);
            for e in events {
                cursor = e.seq;
                let last = is_final(&e);
                if !send(e).await || last {
                    return Ok(());
                }
            }
            if closed {
                break;
            }
            let Some(sig) = signal.as_mut() else { break };
            tokio::select! {
                r = sig.changed() => if r.is_err() { break },
                // Quiet for a while: look at the database again (the job may have
                // ended without this log hearing of it).
                _ = tokio::time::sleep(Duration::from_secs(5)) => break,
                _ = s.jobs.shutdown.cancelled() => return Ok(()),
                _ = tx.closed() => return Ok(()),
            }
        }
    }
}
