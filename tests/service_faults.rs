//! `monocap serve` under faults, with the real binary: a process killed in the middle
//! of a job (the job runs again, nothing is lost), a job that keeps dying (`gave_up`),
//! the bound on jobs tracking at once, SIGTERM (the job goes back to the queue and its
//! attempt does not count) and canceling a running job.
//!
//! The tests share the machine's cores with the jobs they run, so they take turns.

mod common;
#[path = "common/server.rs"]
mod server;

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use common::{monocap, s, TempDir};
use reqwest::blocking::Client;
use serde_json::{json, Value};
use server::{client, Server};

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/bandai_run_20f_masks.zip"
);
const FIXTURE_FRAMES: u64 = 23;
const MOCAP: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/bandai_run_normal_001_20f.bvh"
);
/// Frames of the clip [`long_clip`] makes.
const LONG_FRAMES: u64 = 78;

/// Generous: the machine may be busy with other tests.
const FINISH: Duration = Duration::from_secs(180);

/// One test at a time: each one's timing depends on having the cores to itself.
fn serial() -> MutexGuard<'static, ()> {
    static SERIAL: Mutex<()> = Mutex::new(());
    SERIAL.lock().unwrap_or_else(|p| p.into_inner())
}

fn fixture() -> Vec<u8> {
    std::fs::read(FIXTURE).expect("read the clip fixture")
}

/// A 78-frame silhouette clip (the 20-frame capture at 120 fps): several seconds of
/// tracking with three restarts, so there is time to interrupt it in the middle.
fn long_clip(dir: &TempDir) -> Vec<u8> {
    let out = dir.path("long.zip");
    let res = monocap(&[
        "synth",
        "--bvh",
        MOCAP,
        "--out",
        s(&out),
        "--style",
        "silhouette",
        "--fps",
        "120",
    ]);
    assert!(
        res.status.success(),
        "monocap synth failed: {}",
        String::from_utf8_lossy(&res.stderr)
    );
    std::fs::read(&out).expect("read the synthesised clip")
}

/// `POST /v1/jobs` with the raw clip; the accepted job.
fn submit(http: &Client, base: &str, clip: &[u8], query: &str) -> Value {
    let res = http
        .post(format!("{base}/v1/jobs?{query}"))
        .header("content-type", "application/zip")
        .body(clip.to_vec())
        .send()
        .expect("POST /v1/jobs");
    let status = res.status();
    let body: Value = res.json().expect("JSON answer");
    assert_eq!(status, 202, "submit answered {status}: {body}");
    assert_eq!(body["state"], "queued", "{body}");
    body
}

fn id_of(job: &Value) -> String {
    job["id"].as_str().expect("job id").to_string()
}

fn get_job(http: &Client, base: &str, id: &str) -> Value {
    let res = http
        .get(format!("{base}/v1/jobs/{id}"))
        .send()
        .expect("GET /v1/jobs/{id}");
    assert_eq!(res.status(), 200, "GET job {id}");
    res.json().expect("job JSON")
}

/// Polls the job until `ok` holds; panics with the last answer after `timeout`.
fn wait_job(
    http: &Client,
    base: &str,
    id: &str,
    what: &str,
    timeout: Duration,
    ok: impl Fn(&Value) -> bool,
) -> Value {
    let until = Instant::now() + timeout;
    loop {
        let job = get_job(http, base, id);
        if ok(&job) {
            return job;
        }
        assert!(
            Instant::now() < until,
            "job {id} was not {what} after {timeout:?}; last: {job}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn is_final(job: &Value) -> bool {
    matches!(
        job["state"].as_str(),
        Some("succeeded" | "failed" | "canceled")
    )
}

fn frames_done(job: &Value) -> u64 {
    frames_done_of(&job["progress"])
}

fn frames_done_of(progress: &Value) -> u64 {
    progress["frames_done"].as_u64().unwrap_or(0)
}

/// Waits until the job tracks, with at least one frame done (past its start-up).
fn wait_tracking(http: &Client, base: &str, id: &str) -> Value {
    let job = wait_job(http, base, id, "tracking", FINISH, |j| {
        is_final(j) || (j["state"] == "running" && frames_done(j) > 0)
    });
    assert_eq!(
        job["state"], "running",
        "the job ended before it could be interrupted: {job}"
    );
    job
}

fn wait_final(http: &Client, base: &str, id: &str) -> Value {
    wait_job(http, base, id, "finished", FINISH, is_final)
}

fn wait_succeeded(http: &Client, base: &str, id: &str) -> Value {
    let job = wait_final(http, base, id);
    assert_eq!(job["state"], "succeeded", "job {id}: {job}");
    job
}

/// One server-sent event.
#[derive(Debug)]
struct Sse {
    id: Option<i64>,
    event: String,
    data: Value,
}

/// Parses an event stream (`id:`, `event:`, `data:` lines, a blank line after each
/// event, `:` comments).
fn parse_sse(text: &str) -> Vec<Sse> {
    let mut out = Vec::new();
    let (mut id, mut event, mut data) = (None, String::new(), String::new());
    for line in text.lines() {
        if line.is_empty() {
            if !event.is_empty() || !data.is_empty() {
                let parsed = serde_json::from_str(&data)
                    .unwrap_or_else(|e| panic!("event data is not JSON ({e}): {data}"));
                out.push(Sse {
                    id: id.take(),
                    event: std::mem::take(&mut event),
                    data: parsed,
                });
                data.clear();
            }
            continue;
        }
        if line.starts_with(':') {
            continue;
        }
        let (field, value) = line.split_once(':').unwrap_or((line, ""));
        let value = value.strip_prefix(' ').unwrap_or(value);
        match field {
            "id" => id = Some(value.parse().expect("numeric event id")),
            "event" => event = value.to_string(),
            "data" => {
                if !data.is_empty() {
                    data.push('\n');
                }
                data.push_str(value);
            }
            _ => {}
        }
    }
    assert!(
        event.is_empty() && data.is_empty(),
        "the stream ended inside an event"
    );
    out
}

/// The whole event stream of a finished job (it ends after the final event).
fn history(http: &Client, base: &str, id: &str) -> Vec<Sse> {
    let res = http
        .get(format!("{base}/v1/jobs/{id}/events"))
        .send()
        .expect("GET events");
    assert_eq!(res.status(), 200);
    let ct = res
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    assert!(ct.starts_with("text/event-stream"), "content-type {ct}");
    let events = parse_sse(&res.text().expect("read the stream to its end"));
    assert!(!events.is_empty(), "no events");
    // First the job as it is, without an id; then the stored events in order.
    assert_eq!(events[0].event, "state");
    assert_eq!(events[0].id, None, "the snapshot has no id");
    assert_eq!(events[0].data["id"], id, "the snapshot is the job");
    let ids: Vec<i64> = events[1..]
        .iter()
        .map(|e| {
            e.id.unwrap_or_else(|| panic!("a stored event has no id: {e:?}"))
        })
        .collect();
    assert!(
        ids.windows(2).all(|w| w[0] < w[1]),
        "event ids do not strictly increase: {ids:?}"
    );
    events
}

/// The `state` events after the snapshot, as (state, extra field) pairs.
fn states(events: &[Sse]) -> Vec<Value> {
    events[1..]
        .iter()
        .filter(|e| e.event == "state")
        .map(|e| e.data.clone())
        .collect()
}

/// A thread reading a job's event stream as it comes, keeping the last id seen.
struct Watcher {
    last: Arc<AtomicI64>,
    /// `frames_done` of the last progress event.
    frames: Arc<AtomicU64>,
    thread: std::thread::JoinHandle<()>,
}

impl Watcher {
    /// Waits for the stream to end (the server went away); the last id seen.
    fn finish(self) -> i64 {
        self.thread.join().expect("the watcher thread");
        self.last.load(Ordering::SeqCst)
    }
}

fn watch_events(base: &str, id: &str) -> Watcher {
    let last = Arc::new(AtomicI64::new(0));
    let frames = Arc::new(AtomicU64::new(0));
    let url = format!("{base}/v1/jobs/{id}/events");
    let (seen, done) = (last.clone(), frames.clone());
    let thread = std::thread::spawn(move || {
        let Ok(res) = client().get(url).send() else {
            return;
        };
        let mut progress = false;
        for line in BufReader::new(res).lines() {
            let Ok(line) = line else { return };
            if let Some(v) = line.strip_prefix("id: ") {
                seen.store(v.trim().parse().expect("numeric id"), Ordering::SeqCst);
            } else if let Some(v) = line.strip_prefix("event: ") {
                progress = v == "progress";
            } else if let Some(v) = line.strip_prefix("data: ").filter(|_| progress) {
                let data: Value = serde_json::from_str(v).expect("JSON progress");
                done.store(frames_done_of(&data), Ordering::SeqCst);
            }
        }
    });
    Watcher {
        last,
        frames,
        thread,
    }
}

/// Downloads every file of a succeeded job, checks each is whole, and checks that
/// `motion.bvh` has `frames` frames of motion.
fn check_files(http: &Client, base: &str, job: &Value, frames: u64) {
    let id = id_of(job);
    let artifacts = job["artifacts"].as_array().expect("artifacts");
    let names: BTreeSet<&str> = artifacts
        .iter()
        .filter_map(|a| a["name"].as_str())
        .collect();
    assert_eq!(
        names,
        BTreeSet::from(["model_masks.zip", "motion.bvh", "motion.json"]),
        "job {id}"
    );
    for a in artifacts {
        let url = a["url"].as_str().expect("artifact url");
        let bytes = a["bytes"].as_u64().expect("artifact bytes");
        let res = http.get(format!("{base}{url}")).send().expect("GET file");
        assert_eq!(res.status(), 200, "{url}");
        assert_eq!(
            res.content_length(),
            Some(bytes),
            "{url}: Content-Length against the listed size"
        );
        let body = res.bytes().expect("read the file");
        assert_eq!(body.len() as u64, bytes, "{url}: body length");
        if a["name"] == "motion.bvh" {
            let text = std::str::from_utf8(&body).expect("BVH is text");
            let bvh = monocap::motion::bvh::Bvh::parse(text)
                .unwrap_or_else(|e| panic!("{url} does not parse: {e}"));
            assert_eq!(bvh.frame_count() as u64, frames, "{url}: frames of motion");
            // The same count, read as plain lines.
            let after = text.split_once("Frame Time:").expect("a Frame Time line").1;
            let lines = after.lines().skip(1).filter(|l| !l.trim().is_empty());
            assert_eq!(lines.count() as u64, frames, "{url}: motion lines");
        }
    }
}

/// Milliseconds since the epoch of an RFC 3339 field.
fn ms(v: &Value, field: &str) -> i64 {
    let text = v[field]
        .as_str()
        .unwrap_or_else(|| panic!("{field} missing: {v}"));
    chrono::DateTime::parse_from_rfc3339(text)
        .unwrap_or_else(|e| panic!("{field} {text:?}: {e}"))
        .timestamp_millis()
}

/// Most intervals `[start, end)` covering one instant.
fn max_overlap(spans: &[(i64, i64)]) -> usize {
    spans
        .iter()
        .map(|&(t, _)| spans.iter().filter(|&&(a, b)| a <= t && t < b).count())
        .max()
        .unwrap_or(0)
}

#[test]
fn sse_parser_reads_ids_events_and_comments() {
    let text = ": keep-alive\n\nevent: state\ndata: {\"a\":1}\n\nid: 3\nevent: done\ndata: {}\n\n";
    let e = parse_sse(text);
    assert_eq!(e.len(), 2);
    assert_eq!((e[0].id, e[0].event.as_str()), (None, "state"));
    assert_eq!(e[0].data, json!({"a": 1}));
    assert_eq!((e[1].id, e[1].event.as_str()), (Some(3), "done"));
    assert_eq!(
        max_overlap(&[(0, 10), (10, 20)]),
        1,
        "touching is not overlapping"
    );
    assert_eq!(max_overlap(&[(0, 10), (5, 20), (6, 7)]), 3);
}

#[test]
fn a_killed_service_runs_its_jobs_again_and_loses_none() {
    let _turn = serial();
    let dir = TempDir::new("faults-crash");
    let data = dir.path("data");
    let (long, short) = (long_clip(&dir), fixture());
    let http = client();

    let srv = Server::start(&data, &["--workers", "1"]);
    let a = id_of(&submit(&http, &srv.url, &long, "restarts=3"));
    let b = id_of(&submit(&http, &srv.url, &short, "restarts=3"));
    let c = id_of(&submit(&http, &srv.url, &short, "restarts=3"));
    // A subscriber that is streaming when the process dies.
    let watcher = watch_events(&srv.url, &a);
    let running = wait_tracking(&http, &srv.url, &a);
    assert_eq!(running["attempts"], 1, "{running}");
    for (id, pos) in [(&b, 0), (&c, 1)] {
        let j = get_job(&http, &srv.url, id);
        assert_eq!(j["state"], "queued", "one worker: the others wait: {j}");
        assert_eq!(j["queue_position"], pos, "{j}");
    }
    // Kill it when the stream has shown progress the database does not have yet
    // (it is written twice a second).
    let until = Instant::now() + Duration::from_secs(30);
    while watcher.frames.load(Ordering::SeqCst) <= frames_done(&get_job(&http, &srv.url, &a)) {
        assert!(
            Instant::now() < until,
            "the live stream was never ahead of the database"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    srv.kill();
    let seen = watcher.finish();

    let srv = Server::start(&data, &["--workers", "1"]);
    let jobs: Vec<Value> = [&a, &b, &c]
        .iter()
        .map(|id| wait_succeeded(&http, &srv.url, id))
        .collect();
    assert_eq!(
        jobs[0]["attempts"], 2,
        "the interrupted job ran twice: {}",
        jobs[0]
    );
    assert_eq!(jobs[1]["attempts"], 1, "{}", jobs[1]);
    assert_eq!(jobs[2]["attempts"], 1, "{}", jobs[2]);
    assert_eq!(frames_done(&jobs[0]), LONG_FRAMES, "{}", jobs[0]);

    // Nothing lost, nothing made twice.
    let list: Value = http
        .get(srv.at("/v1/jobs"))
        .send()
        .expect("GET /v1/jobs")
        .json()
        .expect("list JSON");
    let listed: BTreeSet<String> = list["jobs"]
        .as_array()
        .expect("jobs")
        .iter()
        .map(id_of)
        .collect();
    assert_eq!(listed, BTreeSet::from([a.clone(), b.clone(), c.clone()]));
    assert_eq!(list["next_cursor"], Value::Null);

    for (job, frames) in jobs
        .iter()
        .zip([LONG_FRAMES, FIXTURE_FRAMES, FIXTURE_FRAMES])
    {
        assert_eq!(job["clip"]["info"]["frame_count"], frames, "{job}");
        check_files(&http, &srv.url, job, frames);
    }

    // The interrupted job's history: both runs, in order, ending with `done`.
    let events = history(&http, &srv.url, &a);
    let last = events.last().unwrap();
    assert_eq!(last.event, "done", "{last:?}");
    assert_eq!(last.data["state"], "succeeded");
    let runs: Vec<&Value> = events[1..]
        .iter()
        .filter(|e| e.event == "state" && e.data["state"] == "running")
        .map(|e| &e.data["attempt"])
        .collect();
    assert_eq!(runs, [&json!(1), &json!(2)], "running events");
    let st = states(&events);
    assert!(
        st.iter().any(|s| s["state"] == "queued"
            && s["attempts"] == 1
            && s["reason"].as_str().is_some_and(|r| r.contains("stopped"))),
        "no re-queue event after the crash: {st:?}"
    );
    // The subscriber comes back with the last id it saw and misses nothing: event
    // ids the dead process streamed but never stored are not given out again.
    let res = http
        .get(srv.at(&format!("/v1/jobs/{a}/events")))
        .header("last-event-id", seen.to_string())
        .send()
        .unwrap();
    assert_eq!(res.status(), 200);
    let resumed = parse_sse(&res.text().unwrap());
    assert!(
        resumed[1..].iter().all(|e| e.id.is_some_and(|i| i > seen)),
        "resumed after {seen}: {:?}",
        resumed.iter().map(|e| e.id).collect::<Vec<_>>()
    );
    let kinds: Vec<String> = resumed[1..]
        .iter()
        .filter(|e| e.event == "state")
        .map(|e| e.data.to_string())
        .collect();
    assert!(
        resumed[1..]
            .iter()
            .any(|e| e.event == "state" && e.data["state"] == "queued" && e.data["attempts"] == 1),
        "resuming after event {seen} missed the re-queue: {kinds:?}"
    );
    assert!(
        resumed[1..]
            .iter()
            .any(|e| e.event == "state" && e.data["state"] == "running" && e.data["attempt"] == 2),
        "resuming after event {seen} missed the second run: {kinds:?}"
    );
    assert_eq!(resumed.last().unwrap().event, "done");

    // The second run reported every frame.
    let second = events
        .iter()
        .rposition(|e| e.event == "state" && e.data["state"] == "running")
        .unwrap();
    let progress: Vec<u64> = events[second..]
        .iter()
        .filter(|e| e.event == "progress" && e.data["revised"] == false)
        .map(|e| e.data["frames_done"].as_u64().unwrap())
        .collect();
    assert_eq!(
        progress,
        (1..=LONG_FRAMES).collect::<Vec<_>>(),
        "progress of the second run"
    );
    drop(srv);
}

#[test]
fn a_job_that_keeps_dying_gives_up() {
    let _turn = serial();
    let dir = TempDir::new("faults-give-up");
    let data = dir.path("data");
    let long = long_clip(&dir);
    let http = client();
    let args = ["--workers", "1", "--max-attempts", "1"];

    let srv = Server::start(&data, &args);
    let id = id_of(&submit(&http, &srv.url, &long, "restarts=3"));
    wait_tracking(&http, &srv.url, &id);
    srv.kill();

    let srv = Server::start(&data, &args);
    // Recovery runs before the server listens: the job has already failed.
    let job = get_job(&http, &srv.url, &id);
    assert_eq!(job["state"], "failed", "{job}");
    assert_eq!(job["error"]["code"], "gave_up", "{job}");
    assert_eq!(job["attempts"], 1, "{job}");
    assert!(job["finished_at"].is_string(), "{job}");
    assert_eq!(job["artifacts"], json!([]), "{job}");
    let events = history(&http, &srv.url, &id);
    let last = events.last().unwrap();
    assert_eq!(last.event, "failed", "{last:?}");
    assert_eq!(last.data["error"]["code"], "gave_up", "{last:?}");
    // It stays failed (the pool does not pick it up again).
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(get_job(&http, &srv.url, &id)["state"], "failed");
    let res = http
        .get(srv.at(&format!("/v1/jobs/{id}/artifacts/motion.bvh")))
        .send()
        .unwrap();
    assert_eq!(res.status(), 404);

    // Its clip is still there: a rerun tracks it.
    let res = http
        .post(srv.at(&format!("/v1/jobs/{id}/rerun")))
        .body(r#"{"restarts": 1}"#)
        .send()
        .unwrap();
    assert_eq!(res.status(), 202);
    let rerun: Value = res.json().unwrap();
    assert_eq!(rerun["rerun_of"], id.as_str());
    let done = wait_succeeded(&http, &srv.url, &id_of(&rerun));
    check_files(&http, &srv.url, &done, LONG_FRAMES);
}

/// Runs `n` jobs on `workers` workers; the most that tracked at once, from their
/// start and finish times.
fn most_at_once(workers: usize, n: usize) -> usize {
    let dir = TempDir::new("faults-pool");
    let clip = fixture();
    let http = client();
    let srv = Server::start(&dir.path("data"), &["--workers", &workers.to_string()]);
    let ids: Vec<String> = (0..n)
        .map(|_| id_of(&submit(&http, &srv.url, &clip, "restarts=1")))
        .collect();
    let spans: Vec<(i64, i64)> = ids
        .iter()
        .map(|id| {
            let j = wait_succeeded(&http, &srv.url, id);
            assert_eq!(j["attempts"], 1, "{j}");
            let (start, end) = (ms(&j, "started_at"), ms(&j, "finished_at"));
            assert!(start <= end, "{j}");
            assert!(ms(&j, "created_at") <= start, "{j}");
            (start, end)
        })
        .collect();
    max_overlap(&spans)
}

#[test]
fn no_more_jobs_track_at_once_than_workers() {
    let _turn = serial();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let most = most_at_once(2, 5);
    assert!((1..=2).contains(&most), "{most} jobs tracked at once");
    if cores >= 2 {
        assert_eq!(most, 2, "two workers on {cores} cores: two jobs at once");
    }
}

#[test]
fn one_worker_runs_one_job_at_a_time() {
    let _turn = serial();
    assert_eq!(most_at_once(1, 3), 1);
}

#[test]
fn sigterm_puts_the_running_job_back_without_counting_the_attempt() {
    let _turn = serial();
    let dir = TempDir::new("faults-sigterm");
    let data = dir.path("data");
    let long = long_clip(&dir);
    let http = client();

    let srv = Server::start(&data, &["--workers", "1"]);
    let id = id_of(&submit(&http, &srv.url, &long, "restarts=3"));
    wait_tracking(&http, &srv.url, &id);
    let t = Instant::now();
    assert!(
        srv.terminate(Duration::from_secs(10)),
        "the service did not exit with success within 10 s of SIGTERM"
    );
    eprintln!("stopped {:?} after SIGTERM", t.elapsed());

    let srv = Server::start(&data, &["--workers", "1"]);
    let job = wait_succeeded(&http, &srv.url, &id);
    assert_eq!(
        job["attempts"], 1,
        "the interrupted run does not count: {job}"
    );
    assert_eq!(frames_done(&job), LONG_FRAMES, "{job}");
    check_files(&http, &srv.url, &job, LONG_FRAMES);

    let events = history(&http, &srv.url, &id);
    let st: Vec<(String, Value)> = states(&events)
        .into_iter()
        .map(|s| (s["state"].as_str().unwrap_or("").to_string(), s))
        .collect();
    let seq: Vec<&str> = st.iter().map(|(s, _)| s.as_str()).collect();
    assert_eq!(
        seq,
        ["queued", "running", "queued", "running", "succeeded"],
        "state events: {st:?}"
    );
    assert_eq!(st[1].1["attempt"], 1);
    assert!(
        st[2].1["reason"]
            .as_str()
            .is_some_and(|r| r.contains("restarting")),
        "{:?}",
        st[2]
    );
    assert_eq!(st[3].1["attempt"], 1, "the second run is attempt 1 again");
    assert_eq!(events.last().unwrap().event, "done");
}

#[test]
fn canceling_a_running_job_stops_it_within_a_frame() {
    let _turn = serial();
    let dir = TempDir::new("faults-cancel");
    let long = long_clip(&dir);
    let http = client();
    let srv = Server::start(&dir.path("data"), &["--workers", "1"]);
    let a = id_of(&submit(&http, &srv.url, &long, "restarts=3"));
    let b = id_of(&submit(&http, &srv.url, &fixture(), "restarts=1"));
    wait_tracking(&http, &srv.url, &a);

    let t = Instant::now();
    let res = http
        .post(srv.at(&format!("/v1/jobs/{a}/cancel")))
        .send()
        .unwrap();
    assert_eq!(res.status(), 202);
    let answer: Value = res.json().unwrap();
    assert_eq!(answer["cancel_requested"], true, "{answer}");
    let job = wait_job(
        &http,
        &srv.url,
        &a,
        "canceled",
        Duration::from_secs(10),
        is_final,
    );
    let took = t.elapsed();
    assert_eq!(job["state"], "canceled", "{job}");
    assert_eq!(job["error"]["code"], "canceled", "{job}");
    assert_eq!(job["artifacts"], json!([]), "{job}");
    assert!(
        frames_done(&job) < LONG_FRAMES,
        "it stopped before the end: {job}"
    );
    assert!(
        took < Duration::from_secs(3),
        "the job took {took:?} to stop after cancel"
    );

    let events = history(&http, &srv.url, &a);
    let last = events.last().unwrap();
    assert_eq!(last.event, "failed", "{last:?}");
    assert_eq!(last.data["state"], "canceled", "{last:?}");
    assert_eq!(last.data["error"]["code"], "canceled", "{last:?}");

    // Once ended, it cannot be canceled again, and it has no files.
    let res = http
        .post(srv.at(&format!("/v1/jobs/{a}/cancel")))
        .send()
        .unwrap();
    assert_eq!(res.status(), 409);
    let body: Value = res.json().unwrap();
    assert_eq!(body["error"]["code"], "already_finished", "{body}");
    let res = http
        .get(srv.at(&format!("/v1/jobs/{a}/artifacts/motion.bvh")))
        .send()
        .unwrap();
    assert_eq!(res.status(), 404);

    // The freed worker takes the next job.
    let done = wait_succeeded(&http, &srv.url, &b);
    check_files(&http, &srv.url, &done, FIXTURE_FRAMES);
}
