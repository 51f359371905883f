//! A load test of a running `monocap serve`: how fast it answers job polls, and how
//! many progress streams it holds at once.
//!
//! ```text
//! cargo build --release
//! ./target/release/monocap serve --data-dir /tmp/loaddata --listen 127.0.0.1:18181 &
//! cargo run --release --example load -- --url http://127.0.0.1:18181 \
//!     [--token T] [--seconds 10] [--concurrency 32] [--subscribers 1000] [--hold 5] \
//!     [--clip tests/fixtures/bandai_run_20f_masks.zip]
//! ```
//!
//! 1. Submits the clip once (`restarts=1`) and waits for its job to succeed.
//! 2. Polls `GET /v1/jobs/{id}` from `--concurrency` tasks for `--seconds` (half of
//!    them send `If-None-Match` with the job's ETag and get `304`); prints requests/s
//!    and p50/p99/max latency.
//! 3. Keeps the workers busy with slow jobs (`restarts=20`, twice as many as there
//!    are workers), queues one more behind them and opens `--subscribers` event streams on it at once; counts how many got
//!    their first event and how many were still open after `--hold` seconds, while
//!    timing polls on the side. The jobs it queued are canceled at the end.
//!
//! Each subscriber is a connection: raise the open-file limit (`ulimit -n`) of both
//! the server's shell and this one above the subscriber count.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use reqwest::header::{HeaderMap, HeaderValue, AUTHORIZATION, ETAG, IF_NONE_MATCH};
use reqwest::{Client, StatusCode};
use serde_json::Value;

struct Args {
    url: String,
    token: Option<String>,
    seconds: f64,
    concurrency: usize,
    subscribers: usize,
    hold: f64,
    clip: String,
}

const USAGE: &str = "usage: load [--url http://127.0.0.1:8080] [--token T] [--seconds 10] \
    [--concurrency 32] [--subscribers 1000] [--hold 5] [--clip FILE.zip]";

fn parse_args() -> Result<Args> {
    let mut a = Args {
        url: "http://127.0.0.1:8080".into(),
        token: None,
        seconds: 10.0,
        concurrency: 32,
        subscribers: 1000,
        hold: 5.0,
        clip: concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/bandai_run_20f_masks.zip"
        )
        .into(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        if flag == "-h" || flag == "--help" {
            println!("{USAGE}");
            std::process::exit(0);
        }
        let value = it
            .next()
            .with_context(|| format!("{flag} needs a value\n{USAGE}"))?;
        let num = |v: &str| -> Result<f64> {
            v.parse::<f64>()
                .ok()
                .filter(|n| n.is_finite() && *n > 0.0)
                .with_context(|| format!("{flag} {v:?}: expected a positive number"))
        };
        match flag.as_str() {
            "--url" => a.url = value.trim_end_matches('/').to_string(),
            "--token" => a.token = Some(value),
            "--seconds" => a.seconds = num(&value)?,
            "--concurrency" => a.concurrency = num(&value)? as usize,
            "--subscribers" => a.subscribers = num(&value)? as usize,
            "--hold" => a.hold = num(&value)?,
            "--clip" => a.clip = value,
            _ => bail!("unknown flag {flag}\n{USAGE}"),
        }
    }
    a.concurrency = a.concurrency.max(1);
    Ok(a)
}

fn client(token: Option<&str>, timeout: Option<Duration>) -> Result<Client> {
    let mut headers = HeaderMap::new();
    if let Some(t) = token {
        headers.insert(
            AUTHORIZATION,
            HeaderValue::from_str(&format!("Bearer {t}"))?,
        );
    }
    let mut b = Client::builder()
        .default_headers(headers)
        .connect_timeout(Duration::from_secs(10));
    if let Some(t) = timeout {
        b = b.timeout(t);
    }
    Ok(b.build()?)
}

async fn submit(http: &Client, base: &str, clip: &[u8], query: &str) -> Result<String> {
    let res = http
        .post(format!("{base}/v1/jobs?{query}"))
        .header("content-type", "application/zip")
        .body(clip.to_vec())
        .send()
        .await
        .context("POST /v1/jobs")?;
    let status = res.status();
    let body: Value = res.json().await.context("the answer to POST /v1/jobs")?;
    if status != StatusCode::ACCEPTED {
        bail!("POST /v1/jobs answered {status}: {body}");
    }
    Ok(body["id"].as_str().context("no job id")?.to_string())
}

async fn job(http: &Client, base: &str, id: &str) -> Result<Value> {
    let res = http.get(format!("{base}/v1/jobs/{id}")).send().await?;
    if res.status() != StatusCode::OK {
        bail!("GET /v1/jobs/{id} answered {}", res.status());
    }
    Ok(res.json().await?)
}

async fn wait_final(http: &Client, base: &str, id: &str, limit: Duration) -> Result<Value> {
    let until = Instant::now() + limit;
    loop {
        let j = job(http, base, id).await?;
        if matches!(
            j["state"].as_str(),
            Some("succeeded" | "failed" | "canceled")
        ) {
            return Ok(j);
        }
        if Instant::now() > until {
            bail!("job {id} did not finish within {limit:?}: {j}");
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Latencies, sorted.
struct Latencies(Vec<Duration>);

impl Latencies {
    fn new(mut v: Vec<Duration>) -> Latencies {
        v.sort();
        Latencies(v)
    }

    /// Nearest-rank percentile, milliseconds.
    fn pct(&self, q: f64) -> f64 {
        if self.0.is_empty() {
            return f64::NAN;
        }
        let rank = ((q * self.0.len() as f64).ceil() as usize).clamp(1, self.0.len());
        self.0[rank - 1].as_secs_f64() * 1e3
    }

    fn summary(&self) -> String {
        format!(
            "p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
            self.pct(0.50),
            self.pct(0.99),
            self.pct(1.0)
        )
    }
}

#[derive(Default)]
struct PollCounts {
    ok: usize,
    not_modified: usize,
    other: usize,
    errors: usize,
}

/// Polls `url` until `until`, conditionally with `etag`.
async fn poll_loop(
    http: Client,
    url: String,
    etag: Option<String>,
    until: Instant,
) -> (Vec<Duration>, PollCounts) {
    let mut lat = Vec::new();
    let mut c = PollCounts::default();
    while Instant::now() < until {
        let mut req = http.get(&url);
        if let Some(t) = &etag {
            req = req.header(IF_NONE_MATCH, t);
        }
        let t = Instant::now();
        match req.send().await {
            Ok(res) => {
                let status = res.status();
                // The body is part of the answer's cost.
                let whole = res.bytes().await.is_ok();
                lat.push(t.elapsed());
                match status {
                    _ if !whole => c.errors += 1,
                    StatusCode::OK => c.ok += 1,
                    StatusCode::NOT_MODIFIED => c.not_modified += 1,
                    _ => c.other += 1,
                }
            }
            Err(_) => c.errors += 1,
        }
    }
    (lat, c)
}

/// What one event stream did.
#[derive(Default)]
struct Subs {
    connected: AtomicUsize,
    first_event: AtomicUsize,
    held: AtomicUsize,
    ended_early: AtomicUsize,
    failed: AtomicUsize,
}

/// Opens the job's event stream, waits for its first event, then keeps reading
/// until `hold` has passed since `start` (all streams are counted at the same
/// moment).
async fn subscribe(http: Client, url: String, start: Instant, hold: Duration, subs: Arc<Subs>) {
    let mut res = match http.get(&url).send().await {
        Ok(r) if r.status() == StatusCode::OK => r,
        _ => {
            subs.failed.fetch_add(1, Ordering::Relaxed);
            return;
        }
    };
    subs.connected.fetch_add(1, Ordering::Relaxed);
    let mut seen = Vec::new();
    let mut first = false;
    let deadline = tokio::time::Instant::from_std(start + hold);
    loop {
        match tokio::time::timeout_at(deadline, res.chunk()).await {
            // Still open at the deadline.
            Err(_) => {
                if first {
                    subs.held.fetch_add(1, Ordering::Relaxed);
                }
                return;
            }
            Ok(Ok(Some(chunk))) => {
                if !first {
                    seen.extend_from_slice(&chunk);
                    if seen.windows(2).any(|w| w == b"\n\n") {
                        first = true;
                        subs.first_event.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            Ok(Ok(None)) | Ok(Err(_)) => {
                subs.ended_early.fetch_add(1, Ordering::Relaxed);
                return;
            }
        }
    }
}

#[tokio::main]
async fn main() -> Result<()> {
    let a = parse_args()?;
    let base = a.url.clone();
    let http = client(a.token.as_deref(), Some(Duration::from_secs(60)))?;
    let clip = std::fs::read(&a.clip).with_context(|| format!("cannot read {}", a.clip))?;
    let health = http
        .get(format!("{base}/healthz"))
        .send()
        .await
        .with_context(|| format!("no monocap at {base}"))?;
    if !health.status().is_success() {
        bail!("{base}/healthz answered {}", health.status());
    }

    // 1. One job to poll.
    let t = Instant::now();
    let id = submit(&http, &base, &clip, "restarts=1").await?;
    let done = wait_final(&http, &base, &id, Duration::from_secs(600)).await?;
    if done["state"] != "succeeded" {
        bail!("the job did not succeed: {done}");
    }
    println!(
        "job {id}: succeeded in {:.1} s ({} frames)",
        t.elapsed().as_secs_f64(),
        done["progress"]["frames_done"]
    );

    // 2. Polls.
    let url = format!("{base}/v1/jobs/{id}");
    let etag = http
        .get(&url)
        .send()
        .await?
        .headers()
        .get(ETAG)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string)
        .context("GET /v1/jobs/{id} has no ETag")?;
    let pollers = client(a.token.as_deref(), Some(Duration::from_secs(30)))?;
    let until = Instant::now() + Duration::from_secs_f64(a.seconds);
    let start = Instant::now();
    let tasks: Vec<_> = (0..a.concurrency)
        .map(|i| {
            let tag = (i % 2 == 1).then(|| etag.clone());
            tokio::spawn(poll_loop(pollers.clone(), url.clone(), tag, until))
        })
        .collect();
    let mut all = Vec::new();
    let mut counts = PollCounts::default();
    for t in tasks {
        let (lat, c) = t.await?;
        all.extend(lat);
        counts.ok += c.ok;
        counts.not_modified += c.not_modified;
        counts.other += c.other;
        counts.errors += c.errors;
    }
    let elapsed = start.elapsed().as_secs_f64();
    let lat = Latencies::new(all);
    println!(
        "polls: {} requests from {} tasks in {elapsed:.1} s = {:.0} requests/s; {}",
        lat.0.len(),
        a.concurrency,
        lat.0.len() as f64 / elapsed,
        lat.summary()
    );
    println!(
        "polls: {} × 200, {} × 304, {} other statuses, {} transport errors",
        counts.ok, counts.not_modified, counts.other, counts.errors
    );

    // 3. Subscribers on a job that is queued behind slow ones (or running).
    let mut ours = Vec::new();
    let workers = metric(&http, &base, "monocap_workers").await.unwrap_or(2.0) as usize;
    for _ in 0..2 * workers.max(1) {
        ours.push(submit(&http, &base, &clip, "restarts=20").await?);
    }
    let target = submit(&http, &base, &clip, "restarts=20").await?;
    ours.push(target.clone());
    let before = job(&http, &base, &target).await?;
    let hold = Duration::from_secs_f64(a.hold);
    let subs = Arc::new(Subs::default());
    // One connection per stream; no overall timeout (the streams are long).
    let streamer = client(a.token.as_deref(), None)?;
    let events = format!("{base}/v1/jobs/{target}/events");
    let start = Instant::now();
    let tasks: Vec<_> = (0..a.subscribers)
        .map(|_| {
            tokio::spawn(subscribe(
                streamer.clone(),
                events.clone(),
                start,
                hold,
                subs.clone(),
            ))
        })
        .collect();
    // Polls on the side while the streams are open.
    let side = tokio::spawn(poll_loop(pollers.clone(), url.clone(), None, start + hold));
    for t in tasks {
        t.await?;
    }
    let (side_lat, side_counts) = side.await?;
    let after = job(&http, &base, &target).await?;
    println!(
        "subscribers: {} opened on job {target} ({} → {} during the test): {} connected, \
         {} got their first event, {} still open after {:.0} s; {} ended early, {} refused",
        a.subscribers,
        before["state"].as_str().unwrap_or("?"),
        after["state"].as_str().unwrap_or("?"),
        subs.connected.load(Ordering::Relaxed),
        subs.first_event.load(Ordering::Relaxed),
        subs.held.load(Ordering::Relaxed),
        a.hold,
        subs.ended_early.load(Ordering::Relaxed),
        subs.failed.load(Ordering::Relaxed),
    );
    println!(
        "polls while subscribed: {} requests ({} errors); {}",
        side_lat.len(),
        side_counts.errors + side_counts.other,
        Latencies::new(side_lat).summary()
    );

    // Leave the server idle.
    for id in &ours {
        let _ = http
            .post(format!("{base}/v1/jobs/{id}/cancel"))
            .send()
            .await;
    }
    println!("canceled the {} jobs this test queued", ours.len());
    Ok(())
}

/// A gauge from `/metrics`, when metrics are on.
async fn metric(http: &Client, base: &str, name: &str) -> Option<f64> {
    let text = http
        .get(format!("{base}/metrics"))
        .send()
        .await
        .ok()?
        .text()
        .await
        .ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
}
