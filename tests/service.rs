//! `monocap serve` end to end over real TCP: each test starts its own server (a child
//! process on a free loopback port with its own data folder) and talks HTTP to it —
//! uploads, the server-sent event stream (live, late and resumed subscribers), ETags,
//! artifacts with ranges, listing, idempotency, reruns, cancel, delete, probing, API
//! keys, and bad input of every kind (each answered with the right status and JSON
//! error body while the server keeps serving).

mod common;
#[path = "common/server.rs"]
mod server;

use std::collections::BTreeSet;
use std::io::{Read, Write};
use std::pin::Pin;
use std::time::{Duration, Instant};

use common::{monocap, TempDir};
use eventsource_stream::Eventsource;
use futures_util::{Stream, StreamExt};
use reqwest::blocking::{multipart, Client, RequestBuilder, Response};
use reqwest::{Method, StatusCode};
use serde_json::{json, Value};
use server::Server;

/// A ZIP of 23 mask PNGs, 320x240.
const FIXTURE: &str = "tests/fixtures/bandai_run_20f_masks.zip";
const FIXTURE_FRAMES: u64 = 23;
const ARTIFACT_NAMES: [&str; 3] = ["motion.bvh", "motion.json", "model_masks.zip"];

fn fixture() -> Vec<u8> {
    std::fs::read(FIXTURE).expect("read the fixture clip")
}

// ---------------------------------------------------------------------------------
// A server and a client for it.

/// A running server on its own data folder (the server is dropped, and killed,
/// before the folder is removed).
struct Svc {
    server: Server,
    dir: TempDir,
}

impl Svc {
    fn start(tag: &str, args: &[&str]) -> Svc {
        let dir = TempDir::new(tag);
        let server = Server::start(&dir.path("data"), args);
        Svc { server, dir }
    }

    /// Starts a server on a data folder prepared by `prepare` (given the folder).
    fn start_with(tag: &str, args: &[&str], prepare: impl FnOnce(&std::path::Path)) -> Svc {
        let dir = TempDir::new(tag);
        prepare(&dir.path("data"));
        let server = Server::start(&dir.path("data"), args);
        Svc { server, dir }
    }

    fn api(&self, token: Option<&str>) -> Api {
        Api {
            c: server::client(),
            base: self.server.url.clone(),
            token: token.map(str::to_string),
        }
    }

    fn port(&self) -> u16 {
        self.server
            .url
            .rsplit(':')
            .next()
            .and_then(|p| p.parse().ok())
            .expect("the server URL ends with a port")
    }
}

/// A blocking client with an optional API key.
struct Api {
    c: Client,
    base: String,
    token: Option<String>,
}

impl Api {
    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn req(&self, m: Method, path: &str) -> RequestBuilder {
        let r = self.c.request(m, self.url(path));
        match &self.token {
            Some(t) => r.bearer_auth(t),
            None => r,
        }
    }

    fn get(&self, path: &str) -> RequestBuilder {
        self.req(Method::GET, path)
    }

    fn post(&self, path: &str) -> RequestBuilder {
        self.req(Method::POST, path)
    }

    fn delete(&self, path: &str) -> RequestBuilder {
        self.req(Method::DELETE, path)
    }

    /// The fixture as `multipart/form-data` with an `options` part.
    fn submit_multipart(&self, options: &str) -> Value {
        let form = multipart::Form::new()
            .part(
                "clip",
                multipart::Part::bytes(fixture())
                    .file_name("bandai_run_20f_masks.zip")
                    .mime_str("application/zip")
                    .unwrap(),
            )
            .text("options", options.to_string());
        let res = send(self.post("/v1/jobs").multipart(form));
        accepted(res)
    }

    /// The fixture as the raw body, options in the query (`query` starts with `?`
    /// or is empty).
    fn submit_raw(&self, query: &str) -> Value {
        accepted(self.raw_upload(query, "application/zip", fixture(), None))
    }

    fn raw_upload(
        &self,
        query: &str,
        content_type: &str,
        body: Vec<u8>,
        idempotency_key: Option<&str>,
    ) -> Response {
        let mut r = self
            .post(&format!("/v1/jobs{query}"))
            .header("content-type", content_type)
            .body(body);
        if let Some(k) = idempotency_key {
            r = r.header("idempotency-key", k);
        }
        send(r)
    }

    /// `GET /v1/jobs/{id}`, which must answer 200.
    fn job(&self, id: &str) -> Value {
        let res = send(self.get(&format!("/v1/jobs/{id}")));
        assert_eq!(res.status(), StatusCode::OK, "GET job {id}");
        json_body(res)
    }

    /// Polls the job until it has ended.
    fn wait_final(&self, id: &str) -> Value {
        let until = Instant::now() + Duration::from_secs(120);
        loop {
            let job = self.job(id);
            let state = job["state"].as_str().unwrap_or("").to_string();
            if ["succeeded", "failed", "canceled"].contains(&state.as_str()) {
                return job;
            }
            assert!(Instant::now() < until, "job {id} still {state} after 120 s");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Polls the job until it is running (or has ended).
    fn wait_started(&self, id: &str) -> Value {
        let until = Instant::now() + Duration::from_secs(120);
        loop {
            let job = self.job(id);
            if job["state"] != "queued" {
                return job;
            }
            assert!(Instant::now() < until, "job {id} still queued after 120 s");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// A finished job's file, which must answer 200.
    fn artifact(&self, id: &str, name: &str) -> Vec<u8> {
        let res = send(self.get(&format!("/v1/jobs/{id}/artifacts/{name}")));
        assert_eq!(res.status(), StatusCode::OK, "GET {name} of {id}");
        res.bytes().expect("artifact body").to_vec()
    }

    fn motion_json(&self, id: &str) -> Value {
        serde_json::from_slice(&self.artifact(id, "motion.json")).expect("motion.json is JSON")
    }

    /// `GET /v1/jobs?query`, which must answer 200: (ids, next_cursor).
    fn list(&self, query: &str) -> (Vec<String>, Option<String>) {
        let res = send(self.get(&format!("/v1/jobs{query}")));
        assert_eq!(res.status(), StatusCode::OK, "GET /v1/jobs{query}");
        let v = json_body(res);
        let ids = v["jobs"]
            .as_array()
            .unwrap_or_else(|| panic!("jobs is a list: {v}"))
            .iter()
            .map(|j| j["id"].as_str().expect("job id").to_string())
            .collect();
        (ids, v["next_cursor"].as_str().map(str::to_string))
    }

    /// Every page of a listing with `limit` per page.
    fn list_all(&self, filter: &str, limit: u32) -> Vec<String> {
        let mut all = Vec::new();
        let mut cursor: Option<String> = None;
        for _ in 0..100 {
            let mut q = format!("?limit={limit}{filter}");
            if let Some(c) = &cursor {
                q.push_str(&format!("&cursor={c}"));
            }
            let (ids, next) = self.list(&q);
            assert!(
                ids.len() <= limit as usize,
                "page {q} longer than its limit"
            );
            if next.is_some() {
                assert_eq!(ids.len(), limit as usize, "a page before the last is full");
                assert_eq!(next.as_deref(), ids.last().map(String::as_str));
            }
            all.extend(ids);
            match next {
                Some(n) => cursor = Some(n),
                None => return all,
            }
        }
        panic!("more than 100 pages");
    }

    /// The service still answers: `/healthz` and a GET of an existing job.
    fn assert_alive(&self, job: &str, after: &str) {
        let res = send(self.c.get(self.url("/healthz")));
        assert_eq!(res.status(), StatusCode::OK, "healthz after {after}");
        assert_eq!(json_body(res)["status"], "ok");
        let res = send(self.get(&format!("/v1/jobs/{job}")));
        assert_eq!(res.status(), StatusCode::OK, "GET a job after {after}");
        assert_eq!(json_body(res)["id"], job);
    }
}

fn send(r: RequestBuilder) -> Response {
    r.send().expect("the server answers")
}

fn json_body(res: Response) -> Value {
    let text = res.text().expect("body");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("not JSON ({e}): {text:?}"))
}

fn header(res: &Response, name: &str) -> Option<String> {
    res.headers()
        .get(name)
        .map(|v| v.to_str().expect("ASCII header").to_string())
}

/// A 202 with a queued job and its Location.
fn accepted(res: Response) -> Value {
    let status = res.status();
    let location = header(&res, "location");
    let text = res.text().expect("body");
    assert_eq!(status, StatusCode::ACCEPTED, "submit: {text}");
    let job: Value = serde_json::from_str(&text).expect("job JSON");
    let id = job["id"].as_str().expect("job id");
    assert_eq!(location.as_deref(), Some(format!("/v1/jobs/{id}").as_str()));
    job
}

fn id_of(job: &Value) -> String {
    job["id"].as_str().expect("job id").to_string()
}

/// An error answer: the status, a JSON body `{"error":{"code","message"}}` with the
/// code and a message. Returns the message.
#[track_caller]
fn assert_error(res: Response, status: StatusCode, code: &str, what: &str) -> String {
    let got = res.status();
    let ct = header(&res, "content-type").unwrap_or_default();
    let text = res.text().expect("body");
    check_error_parts(got, &ct, &text, status, code, what)
}

#[track_caller]
fn check_error_parts(
    got: StatusCode,
    ct: &str,
    text: &str,
    status: StatusCode,
    code: &str,
    what: &str,
) -> String {
    println!("{what}: {got} {text}");
    assert_eq!(got, status, "{what}: status (body {text})");
    assert!(
        ct.starts_with("application/json"),
        "{what}: Content-Type {ct:?}, expected JSON (body {text})"
    );
    let v: Value = serde_json::from_str(text)
        .unwrap_or_else(|e| panic!("{what}: error body is not JSON ({e}): {text:?}"));
    assert_eq!(v["error"]["code"], code, "{what}: error code in {text}");
    let msg = v["error"]["message"]
        .as_str()
        .unwrap_or_else(|| panic!("{what}: no error message in {text}"));
    assert!(!msg.trim().is_empty(), "{what}: empty error message");
    msg.to_string()
}

/// The boundary of hand-made multipart bodies.
const BOUNDARY: &str = "XyZbOuNdArY";

/// A `multipart/form-data` body with [`BOUNDARY`]: parts (name, file name, bytes),
/// and the closing boundary when `end`.
fn multipart_body(parts: &[(&str, Option<&str>, &[u8])], end: bool) -> Vec<u8> {
    let mut b = Vec::new();
    for (name, file, data) in parts {
        b.extend_from_slice(format!("--{BOUNDARY}\r\n").as_bytes());
        let head = match file {
            Some(f) => format!(
                "Content-Disposition: form-data; name=\"{name}\"; filename=\"{f}\"\r\n\
                 Content-Type: application/zip\r\n\r\n"
            ),
            None => format!("Content-Disposition: form-data; name=\"{name}\"\r\n\r\n"),
        };
        b.extend_from_slice(head.as_bytes());
        b.extend_from_slice(data);
        b.extend_from_slice(b"\r\n");
    }
    if end {
        b.extend_from_slice(format!("--{BOUNDARY}--\r\n").as_bytes());
    }
    b
}

/// Motion JSON frame indices.
fn frame_indices(motion: &Value) -> Vec<u64> {
    motion["frames"]
        .as_array()
        .expect("motion frames")
        .iter()
        .map(|f| f["index"].as_u64().expect("frame index"))
        .collect()
}

fn bvh_frames(bytes: &[u8]) -> usize {
    let text = std::str::from_utf8(bytes).expect("BVH is UTF-8");
    monocap::motion::bvh::Bvh::parse(text)
        .expect("motion.bvh parses")
        .frame_count()
}

/// A raw HTTP/1.1 exchange over TCP: sends `request`, returns what comes back until
/// the server closes or 10 s pass.
fn raw_http(port: u16, request: &[u8]) -> String {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).expect("send");
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                out.extend_from_slice(&buf[..n]);
                // Enough once a whole small response is in.
                let text = String::from_utf8_lossy(&out);
                if let Some((head, body)) = text.split_once("\r\n\r\n") {
                    let len = head
                        .lines()
                        .find_map(|l| {
                            let (k, v) = l.split_once(':')?;
                            k.eq_ignore_ascii_case("content-length")
                                .then(|| v.trim().parse::<usize>().ok())?
                        })
                        .unwrap_or(usize::MAX);
                    if body.len() >= len {
                        break;
                    }
                }
            }
            Err(_) => break,
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

// ---------------------------------------------------------------------------------
// Server-sent events.

/// One event as received: its id (none for the first, the job's snapshot), name and
/// JSON data.
#[derive(Clone, Debug, PartialEq)]
struct Ev {
    id: Option<i64>,
    event: String,
    data: Value,
}

type Events = Pin<Box<dyn Stream<Item = Ev> + Send>>;

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime")
}

fn async_client() -> reqwest::Client {
    reqwest::Client::builder().build().expect("async client")
}

/// Opens the job's event stream (optionally resuming after `last`).
async fn subscribe(
    c: &reqwest::Client,
    base: &str,
    token: Option<&str>,
    id: &str,
    last: Option<i64>,
) -> Events {
    let mut r = c
        .get(format!("{base}/v1/jobs/{id}/events"))
        .header("accept", "text/event-stream");
    if let Some(t) = token {
        r = r.bearer_auth(t);
    }
    if let Some(l) = last {
        r = r.header("last-event-id", l.to_string());
    }
    let res = tokio::time::timeout(Duration::from_secs(30), r.send())
        .await
        .expect("the events route answers within 30 s")
        .expect("events request");
    assert_eq!(res.status(), StatusCode::OK, "events of {id}");
    let ct = res
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    assert!(
        ct.starts_with("text/event-stream"),
        "events Content-Type {ct:?}"
    );
    Box::pin(res.bytes_stream().eventsource().map(|r| {
        let e = r.expect("a well-formed event stream");
        Ev {
            id: (!e.id.is_empty()).then(|| e.id.parse().expect("integer event id")),
            data: serde_json::from_str(&e.data)
                .unwrap_or_else(|err| panic!("event data is not JSON ({err}): {:?}", e.data)),
            event: e.event,
        }
    }))
}

/// The next event (None when the stream ended).
async fn next_event(s: &mut Events) -> Option<Ev> {
    tokio::time::timeout(Duration::from_secs(60), s.next())
        .await
        .expect("an event (or the end of the stream) within 60 s")
}

/// Every event until the stream ends.
async fn drain(mut s: Events) -> Vec<Ev> {
    let mut out = Vec::new();
    while let Some(e) = next_event(&mut s).await {
        out.push(e);
    }
    out
}

/// The whole stream of a job, from the start.
fn all_events(base: &str, token: Option<&str>, id: &str, last: Option<i64>) -> Vec<Ev> {
    runtime().block_on(async {
        let c = async_client();
        drain(subscribe(&c, base, token, id, last).await).await
    })
}

/// The stream's snapshot (first event) and its stored events.
fn split_snapshot<'a>(events: &'a [Ev], id: &str) -> (&'a Ev, &'a [Ev]) {
    let (first, rest) = events.split_first().expect("at least the snapshot event");
    assert_eq!(
        first.event, "state",
        "the first event is `state`: {first:?}"
    );
    assert_eq!(first.id, None, "the snapshot has no id: {first:?}");
    assert_eq!(first.data["id"], id, "the snapshot is the job: {first:?}");
    for e in rest {
        assert!(e.id.is_some(), "stored events have ids: {e:?}");
    }
    (first, rest)
}

fn ids(events: &[Ev]) -> Vec<i64> {
    events.iter().map(|e| e.id.expect("event id")).collect()
}

/// The stored events of a successful job, in full: `state` queued, `state` running
/// (attempt 1), one `progress` per frame of `frames` (tracking order; and again,
/// `revised`, for a frame whose answer the second pass replaced), `state`
/// succeeded, `done` with the three files; ids contiguous and increasing.
fn check_success_events(stored: &[Ev], frames: std::ops::Range<u64>) {
    let n = (frames.end - frames.start) as usize;
    let kinds: Vec<&str> = stored.iter().map(|e| e.event.as_str()).collect();
    let end = kinds.len().saturating_sub(2).max(2);
    let revisions = stored[2..end]
        .iter()
        .filter(|e| e.data["revised"] == json!(true))
        .count();
    let mut want = vec!["state", "state"];
    want.extend(std::iter::repeat_n("progress", n + revisions));
    want.extend(["state", "done"]);
    assert_eq!(kinds, want, "event kinds");
    let seq = ids(stored);
    assert!(
        seq.windows(2).all(|w| w[1] == w[0] + 1),
        "ids increase by one (no gaps, no repeats): {seq:?}"
    );
    assert!(seq[0] >= 1, "ids are positive: {seq:?}");
    assert_eq!(stored[0].data, json!({ "state": "queued" }));
    assert_eq!(stored[1].data, json!({ "state": "running", "attempt": 1 }));
    let mut seen = BTreeSet::new();
    for e in &stored[2..end] {
        let d = &e.data;
        if d["revised"] == json!(true) {
            let f = d["frame"].as_u64().unwrap_or_else(|| panic!("frame: {d}"));
            assert!(seen.contains(&f), "frame {f} revised before it came: {d}");
            assert_eq!(d["frames_done"], json!(seen.len()), "a revision: {d}");
            continue;
        }
        assert_eq!(d["revised"], json!(false), "revised: {d}");
        assert_eq!(
            d["frames_done"],
            json!(seen.len() + 1),
            "frames_done in order: {d}"
        );
        assert_eq!(d["frames_total"], json!(n), "frames_total: {d}");
        let f = d["frame"].as_u64().unwrap_or_else(|| panic!("frame: {d}"));
        assert!(frames.contains(&f), "frame {f} outside {frames:?}");
        assert!(seen.insert(f), "frame {f} reported twice");
        assert!(d["person"].is_boolean(), "person: {d}");
        assert!(d["fps"].is_number(), "fps: {d}");
        assert!(d.get("cost").is_some() && d.get("iou").is_some(), "{d}");
    }
    assert_eq!(seen, frames.collect::<BTreeSet<_>>(), "every frame once");
    assert_eq!(stored[end].data, json!({ "state": "succeeded" }));
    let done = &stored[end + 1].data;
    assert_eq!(done["state"], "succeeded");
    let names: BTreeSet<&str> = done["artifacts"]
        .as_array()
        .expect("done lists artifacts")
        .iter()
        .map(|a| a["name"].as_str().expect("artifact name"))
        .collect();
    assert_eq!(names, ARTIFACT_NAMES.into_iter().collect());
}

// ---------------------------------------------------------------------------------
// The tests.

/// Upload (multipart) → live events → ETag polling → artifacts with ranges.
#[test]
fn a_job_streams_its_progress_and_serves_its_files() {
    let svc = Svc::start("svc-flow", &[]);
    let api = svc.api(None);
    let job = api.submit_multipart(r#"{"restarts": 1}"#);
    let id = id_of(&job);
    assert_eq!(job["state"], "queued");
    assert_eq!(job["options"], json!({ "restarts": 1 }));
    assert_eq!(job["clip"]["name"], "bandai_run_20f_masks.zip");
    assert_eq!(job["clip"]["info"]["frame_count"], FIXTURE_FRAMES);

    // Poll with If-None-Match while the events stream.
    let poller = {
        let base = api.base.clone();
        let id = id.clone();
        std::thread::spawn(move || {
            let c = server::client();
            let mut etag: Option<String> = None;
            let mut states = Vec::new();
            let mut not_modified = 0;
            let until = Instant::now() + Duration::from_secs(120);
            loop {
                let mut r = c.get(format!("{base}/v1/jobs/{id}"));
                if let Some(t) = &etag {
                    r = r.header("if-none-match", t);
                }
                let res = send(r);
                let tag = header(&res, "etag").expect("GET job has an ETag");
                match res.status() {
                    StatusCode::NOT_MODIFIED => {
                        assert_eq!(Some(&tag), etag.as_ref(), "304 keeps the ETag");
                        assert!(res.bytes().unwrap().is_empty(), "304 has no body");
                        not_modified += 1;
                    }
                    StatusCode::OK => {
                        assert_ne!(
                            Some(&tag),
                            etag.as_ref(),
                            "a 200 to If-None-Match means the ETag changed"
                        );
                        let v = json_body(res);
                        let state = v["state"].as_str().unwrap().to_string();
                        if states.last() != Some(&state) {
                            states.push(state.clone());
                        }
                        etag = Some(tag);
                        if state == "succeeded" || state == "failed" || state == "canceled" {
                            return (states, not_modified, etag.unwrap());
                        }
                    }
                    s => panic!("GET job while polling: {s}"),
                }
                assert!(Instant::now() < until, "the job never ended");
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };

    let events = all_events(&api.base, None, &id, None);
    let (snapshot, stored) = split_snapshot(&events, &id);
    assert!(
        ["queued", "running"].contains(&snapshot.data["state"].as_str().unwrap()),
        "snapshot of a new job: {:?}",
        snapshot.data["state"]
    );
    check_success_events(stored, 0..FIXTURE_FRAMES);

    let (states, not_modified, etag) = poller.join().expect("poller");
    println!("polled states {states:?}, {not_modified} × 304");
    let order = ["queued", "running", "succeeded"];
    let pos: Vec<usize> = states
        .iter()
        .map(|s| order.iter().position(|o| o == s).expect("known state"))
        .collect();
    assert!(
        pos.windows(2).all(|w| w[0] < w[1]),
        "states move on: {states:?}"
    );
    assert_eq!(states.last().map(String::as_str), Some("succeeded"));
    assert!(not_modified > 0, "an unchanged job answers 304");
    for _ in 0..2 {
        let res = send(
            api.get(&format!("/v1/jobs/{id}"))
                .header("if-none-match", &etag),
        );
        assert_eq!(
            res.status(),
            StatusCode::NOT_MODIFIED,
            "finished job, same ETag"
        );
        assert_eq!(header(&res, "etag").as_deref(), Some(etag.as_str()));
    }
    let res = send(
        api.get(&format!("/v1/jobs/{id}"))
            .header("if-none-match", "\"stale\""),
    );
    assert_eq!(res.status(), StatusCode::OK, "another ETag gets the job");

    let job = api.job(&id);
    assert_eq!(job["state"], "succeeded");
    assert_eq!(job["progress"]["frames_done"], FIXTURE_FRAMES);
    assert_eq!(job["progress"]["frames_total"], FIXTURE_FRAMES);
    assert_eq!(job["error"], Value::Null);
    let done = &stored.last().unwrap().data;
    let listed = job["artifacts"].as_array().expect("artifacts");
    assert_eq!(listed.len(), 3);
    for a in listed {
        let name = a["name"].as_str().unwrap();
        assert_eq!(
            a["url"],
            format!("/v1/jobs/{id}/artifacts/{name}"),
            "artifact url"
        );
        let in_done = done["artifacts"]
            .as_array()
            .unwrap()
            .iter()
            .find(|d| d["name"] == name)
            .expect("the same files in `done`");
        assert_eq!(in_done["bytes"], a["bytes"]);
    }

    // The files.
    for (name, ct) in [
        ("motion.bvh", "application/octet-stream"),
        ("motion.json", "application/json"),
        ("model_masks.zip", "application/zip"),
    ] {
        let res = send(api.get(&format!("/v1/jobs/{id}/artifacts/{name}")));
        assert_eq!(res.status(), StatusCode::OK, "{name}");
        assert_eq!(header(&res, "content-type").as_deref(), Some(ct), "{name}");
        let cd = header(&res, "content-disposition").unwrap_or_default();
        assert!(
            cd.starts_with("attachment") && cd.contains(&format!("filename=\"{name}\"")),
            "{name}: Content-Disposition {cd:?}"
        );
        let tag = header(&res, "etag").expect("artifact ETag");
        assert!(
            tag.starts_with('"') && !tag.starts_with("W/"),
            "strong ETag {tag}"
        );
        let want = listed.iter().find(|a| a["name"] == name).unwrap()["bytes"]
            .as_u64()
            .unwrap();
        let body = res.bytes().unwrap().to_vec();
        assert_eq!(body.len() as u64, want, "{name}: size as listed");

        let res = send(
            api.get(&format!("/v1/jobs/{id}/artifacts/{name}"))
                .header("if-none-match", &tag),
        );
        assert_eq!(
            res.status(),
            StatusCode::NOT_MODIFIED,
            "{name}: If-None-Match"
        );
        assert_eq!(header(&res, "etag").as_deref(), Some(tag.as_str()));
        assert!(res.bytes().unwrap().is_empty());

        let len = body.len();
        for (range, a, b) in [
            ("bytes=10-99".to_string(), 10, 99),
            ("bytes=-16".to_string(), len - 16, len - 1),
            ("bytes=100-".to_string(), 100, len - 1),
            (format!("bytes={}-{}", len - 5, len + 100), len - 5, len - 1),
        ] {
            let res = send(
                api.get(&format!("/v1/jobs/{id}/artifacts/{name}"))
                    .header("range", &range),
            );
            assert_eq!(res.status(), StatusCode::PARTIAL_CONTENT, "{name} {range}");
            assert_eq!(
                header(&res, "content-range"),
                Some(format!("bytes {a}-{b}/{len}")),
                "{name} {range}"
            );
            let part = res.bytes().unwrap();
            assert_eq!(&part[..], &body[a..=b], "{name} {range}: the right bytes");
        }
        // Several ranges: the whole file.
        let res = send(
            api.get(&format!("/v1/jobs/{id}/artifacts/{name}"))
                .header("range", "bytes=0-1,4-5"),
        );
        assert_eq!(res.status(), StatusCode::OK, "{name}: several ranges");
        assert_eq!(res.bytes().unwrap().len(), len);
        // A stale If-Range gets the whole file.
        let res = send(
            api.get(&format!("/v1/jobs/{id}/artifacts/{name}"))
                .header("range", "bytes=0-9")
                .header("if-range", "\"stale\""),
        );
        assert_eq!(res.status(), StatusCode::OK, "{name}: stale If-Range");
        assert_eq!(res.bytes().unwrap().len(), len);

        match name {
            "motion.bvh" => assert_eq!(bvh_frames(&body), FIXTURE_FRAMES as usize),
            "motion.json" => {
                let m: Value = serde_json::from_slice(&body).expect("motion.json");
                assert_eq!(m["format"], "monocap.motion/1");
                assert_eq!(m["frame_count"], FIXTURE_FRAMES);
                assert_eq!(frame_indices(&m), (0..FIXTURE_FRAMES).collect::<Vec<_>>());
            }
            _ => assert!(body.starts_with(b"PK\x03\x04"), "model_masks.zip is a ZIP"),
        }
    }
    let res = send(api.get(&format!("/v1/jobs/{id}/artifacts/nope.txt")));
    assert_error(res, StatusCode::NOT_FOUND, "not_found", "unknown artifact");
}

/// Subscribers that come late (while the job runs) get the whole history; a
/// reconnect with `Last-Event-ID` gets exactly what came after.
#[test]
fn late_and_resumed_subscribers_miss_nothing() {
    let svc = Svc::start("svc-resume", &[]);
    let api = svc.api(None);
    // Two restarts: the job runs long enough to subscribe while it tracks.
    let id = id_of(&api.submit_raw("?restarts=2"));
    let base = api.base.clone();

    let (a, b1, b1_snapshot_state, b2, p1) = runtime().block_on(async {
        let c = async_client();
        let mut a = subscribe(&c, &base, None, &id, None).await;
        let mut a_seen = Vec::new();
        // Up to `running`: the tracker has just started.
        loop {
            let e = next_event(&mut a).await.expect("the stream goes on");
            let running = e.event == "state" && e.data["state"] == "running" && e.id.is_some();
            a_seen.push(e);
            if running {
                break;
            }
        }
        let mut b1 = subscribe(&c, &base, None, &id, None).await;
        let b1_first = next_event(&mut b1).await.expect("the snapshot");
        let b1_state = b1_first.data["state"].as_str().unwrap_or("").to_string();
        // Up to the first progress event, then a resuming subscriber.
        let p1 = loop {
            let e = next_event(&mut a).await.expect("the stream goes on");
            let progress = e.event == "progress";
            let id = e.id;
            a_seen.push(e);
            if progress {
                break id.expect("progress id");
            }
        };
        let b2 = subscribe(&c, &base, None, &id, Some(p1)).await;
        let (a_rest, b1_rest, b2_all) = tokio::join!(drain(a), drain(b1), drain(b2));
        a_seen.extend(a_rest);
        let mut b1_all = vec![b1_first];
        b1_all.extend(b1_rest);
        (a_seen, b1_all, b1_state, b2_all, p1)
    });

    let (_, a_stored) = split_snapshot(&a, &id);
    check_success_events(a_stored, 0..FIXTURE_FRAMES);
    let (_, b1_stored) = split_snapshot(&b1, &id);
    assert_eq!(
        b1_snapshot_state, "running",
        "the late subscriber came while the job was running"
    );
    assert_eq!(
        b1_stored, a_stored,
        "a late subscriber gets the whole history"
    );
    let (_, b2_stored) = split_snapshot(&b2, &id);
    let after_p1: Vec<Ev> = a_stored
        .iter()
        .filter(|e| e.id.unwrap() > p1)
        .cloned()
        .collect();
    assert_eq!(b2_stored, &after_p1[..], "resumed while running after {p1}");

    // After the job: resume from several points.
    let all_ids = ids(a_stored);
    let last = *all_ids.last().unwrap();
    for k in [
        0,
        all_ids[0],
        all_ids[1],
        all_ids[5],
        all_ids[20],
        last - 1,
        last,
    ] {
        let events = all_events(&base, None, &id, Some(k));
        let (snapshot, stored) = split_snapshot(&events, &id);
        assert_eq!(snapshot.data["state"], "succeeded");
        let want: Vec<Ev> = a_stored
            .iter()
            .filter(|e| e.id.unwrap() > k)
            .cloned()
            .collect();
        assert_eq!(stored, &want[..], "Last-Event-ID {k}");
        if k < last {
            assert_eq!(stored.last().unwrap().event, "done", "ends with done");
        }
    }
    // An id past the end: nothing more, and the stream ends.
    let events = all_events(&base, None, &id, Some(last + 100));
    assert_eq!(events.len(), 1, "only the snapshot: {events:?}");
}

/// Raw uploads with query options, idempotency, frame ranges, reruns, listing,
/// cancel, delete and probing.
#[test]
fn jobs_are_listed_rerun_canceled_and_deleted() {
    let svc = Svc::start("svc-crud", &[]);
    let api = svc.api(None);

    // Probe first (no job).
    let res = send(
        api.post("/v1/probe")
            .header("content-type", "application/zip")
            .body(fixture()),
    );
    assert_eq!(res.status(), StatusCode::OK, "probe");
    let info = json_body(res);
    assert_eq!(info["container"], "zip");
    assert_eq!(info["codec"], "png");
    assert_eq!(info["width"], 320);
    assert_eq!(info["height"], 240);
    assert_eq!(info["frame_count"], FIXTURE_FRAMES);
    assert!(info["fps"].is_number() && info["duration_s"].is_number());
    let form =
        multipart::Form::new().part("clip", multipart::Part::bytes(fixture()).file_name("c.zip"));
    let res = send(api.post("/v1/probe").multipart(form));
    assert_eq!(res.status(), StatusCode::OK, "multipart probe");
    assert_eq!(json_body(res), info);
    assert_eq!(api.list("").0.len(), 0, "probing makes no job");

    // Raw body, options in the query, idempotent.
    let first = api.raw_upload(
        "?restarts=1&frames=5..15",
        "application/zip",
        fixture(),
        Some("upload-1"),
    );
    let job1 = accepted(first);
    let id1 = id_of(&job1);
    assert_eq!(job1["options"], json!({ "restarts": 1, "frames": "5..15" }));
    assert_eq!(job1["clip"]["name"], "clip");
    let again = accepted(api.raw_upload(
        "?restarts=1&frames=5..15",
        "application/zip",
        fixture(),
        Some("upload-1"),
    ));
    assert_eq!(id_of(&again), id1, "the same Idempotency-Key, the same job");
    assert_eq!(api.list("").0, vec![id1.clone()], "one job listed");

    // The same key from several clients at once: one job.
    let racers: Vec<_> = (0..4)
        .map(|_| {
            let base = api.base.clone();
            std::thread::spawn(move || {
                let api = Api {
                    c: server::client(),
                    base,
                    token: None,
                };
                id_of(&accepted(api.raw_upload(
                    "?restarts=1",
                    "application/zip",
                    fixture(),
                    Some("upload-2"),
                )))
            })
        })
        .collect();
    let raced: BTreeSet<String> = racers.into_iter().map(|t| t.join().unwrap()).collect();
    assert_eq!(raced.len(), 1, "concurrent uploads with one key: {raced:?}");
    let id2 = id_of(&accepted(api.raw_upload(
        "?restarts=1",
        "application/octet-stream",
        fixture(),
        Some("upload-2"),
    )));
    assert_ne!(id2, id1);
    assert!(raced.contains(&id2), "the racers' job");
    assert_eq!(api.list("").0, vec![id2.clone(), id1.clone()]);

    // frames=5..15: ten frames, clip indices 5..=14.
    let events = all_events(&api.base, None, &id1, None);
    let (_, stored) = split_snapshot(&events, &id1);
    check_success_events(stored, 5..15);
    let done1 = api.wait_final(&id1);
    assert_eq!(done1["state"], "succeeded");
    assert_eq!(done1["progress"]["frames_total"], 10);
    assert_eq!(
        frame_indices(&api.motion_json(&id1)),
        (5..15).collect::<Vec<_>>()
    );
    assert_eq!(bvh_frames(&api.artifact(&id1, "motion.bvh")), 10);
    assert_eq!(api.wait_final(&id2)["state"], "succeeded");

    // A rerun with new options over the old.
    let res = send(
        api.post(&format!("/v1/jobs/{id1}/rerun"))
            .header("content-type", "application/json")
            .body(r#"{"frames": "10..20"}"#),
    );
    let job3 = accepted(res);
    let id3 = id_of(&job3);
    assert_ne!(id3, id1);
    assert_eq!(job3["rerun_of"], id1.as_str());
    assert_eq!(
        job3["options"],
        json!({ "restarts": 1, "frames": "10..20" })
    );
    assert_eq!(job3["clip"], done1["clip"], "the same clip");
    let done3 = api.wait_final(&id3);
    assert_eq!(done3["state"], "succeeded", "{done3}");
    assert_eq!(
        frame_indices(&api.motion_json(&id3)),
        (10..20).collect::<Vec<_>>()
    );
    for (body, what) in [
        (r#"{"restarts": 0}"#, "rerun restarts=0"),
        (r#"{"bogus": 1}"#, "rerun unknown option"),
        ("not json", "rerun body not JSON"),
        (r#"{"frames": "30..40"}"#, "rerun frames past the clip"),
    ] {
        let res = send(api.post(&format!("/v1/jobs/{id1}/rerun")).body(body));
        assert_error(res, StatusCode::UNPROCESSABLE_ENTITY, "bad_options", what);
    }

    // Cancel: a finished job cannot be; a fresh one can.
    let res = send(api.post(&format!("/v1/jobs/{id1}/cancel")));
    assert_error(
        res,
        StatusCode::CONFLICT,
        "already_finished",
        "cancel a finished job",
    );
    let id4 = id_of(&api.submit_raw("?restarts=1"));
    let res = send(api.post(&format!("/v1/jobs/{id4}/cancel")));
    assert_eq!(res.status(), StatusCode::ACCEPTED, "cancel a new job");
    let v = json_body(res);
    assert_eq!(v["id"], id4.as_str());
    assert!(
        v["cancel_requested"] == true || v["state"] == "canceled",
        "cancel answers the job: {v}"
    );
    let done4 = api.wait_final(&id4);
    assert_eq!(done4["state"], "canceled", "{done4}");
    assert_eq!(done4["error"]["code"], "canceled");
    assert_eq!(done4["artifacts"], json!([]));
    let events = all_events(&api.base, None, &id4, None);
    let (_, stored) = split_snapshot(&events, &id4);
    let last = stored.last().expect("stored events");
    assert_eq!(
        last.event, "failed",
        "a canceled job's stream ends with failed"
    );
    assert_eq!(last.data["state"], "canceled");
    assert_eq!(last.data["error"]["code"], "canceled");
    let res = send(api.post(&format!("/v1/jobs/{id4}/cancel")));
    assert_error(
        res,
        StatusCode::CONFLICT,
        "already_finished",
        "cancel twice",
    );
    let res = send(api.get(&format!("/v1/jobs/{id4}/artifacts/motion.bvh")));
    assert_error(
        res,
        StatusCode::NOT_FOUND,
        "not_found",
        "files of a canceled job",
    );

    // Listing: newest first, in pages, by state.
    let newest_first = vec![id4.clone(), id3.clone(), id2.clone(), id1.clone()];
    assert_eq!(api.list("").0, newest_first);
    assert_eq!(api.list_all("", 1), newest_first, "pages of 1");
    assert_eq!(api.list_all("", 3), newest_first, "pages of 3");
    let (page, next) = api.list("?limit=1");
    assert_eq!(page, vec![id4.clone()]);
    assert_eq!(next.as_deref(), Some(id4.as_str()));
    let (page, _) = api.list(&format!("?limit=2&cursor={id3}"));
    assert_eq!(page, vec![id2.clone(), id1.clone()], "after a cursor");
    assert_eq!(
        api.list_all("&state=succeeded", 2),
        vec![id3.clone(), id2.clone(), id1.clone()]
    );
    assert_eq!(api.list("?state=canceled").0, vec![id4.clone()]);
    assert_eq!(api.list("?state=queued").0, Vec::<String>::new());
    assert_eq!(api.list("?state=running").0, Vec::<String>::new());

    // Delete.
    let res = send(api.delete(&format!("/v1/jobs/{id2}")));
    assert_eq!(res.status(), StatusCode::NO_CONTENT, "delete");
    for (m, path, what) in [
        (Method::GET, format!("/v1/jobs/{id2}"), "GET a deleted job"),
        (
            Method::GET,
            format!("/v1/jobs/{id2}/artifacts/motion.bvh"),
            "a deleted job's file",
        ),
        (
            Method::GET,
            format!("/v1/jobs/{id2}/events"),
            "a deleted job's events",
        ),
        (
            Method::POST,
            format!("/v1/jobs/{id2}/cancel"),
            "cancel a deleted job",
        ),
        (
            Method::POST,
            format!("/v1/jobs/{id2}/rerun"),
            "rerun a deleted job",
        ),
        (Method::DELETE, format!("/v1/jobs/{id2}"), "delete twice"),
    ] {
        let res = send(api.req(m, &path));
        assert_error(res, StatusCode::NOT_FOUND, "not_found", what);
    }
    assert_eq!(api.list("").0, vec![id4.clone(), id3.clone(), id1.clone()]);

    // Deleting the first job of a clip keeps the clip for its rerun.
    let res = send(api.delete(&format!("/v1/jobs/{id1}")));
    assert_eq!(
        res.status(),
        StatusCode::NO_CONTENT,
        "delete the rerun's origin"
    );
    assert_eq!(
        api.artifact(&id3, "motion.bvh").len() as u64,
        done3["artifacts"][0]["bytes"].as_u64().unwrap(),
        "the rerun's files stay"
    );
    let res = send(
        api.post(&format!("/v1/jobs/{id3}/rerun"))
            .body(r#"{"frames": "0..6"}"#),
    );
    let id5 = id_of(&accepted(res));
    let done5 = api.wait_final(&id5);
    assert_eq!(
        done5["state"], "succeeded",
        "rerun on a shared clip: {done5}"
    );
    assert_eq!(
        frame_indices(&api.motion_json(&id5)),
        (0..6).collect::<Vec<_>>()
    );

    // Deleting a running job cancels it first; its subscribers see it end.
    let id6 = id_of(&api.submit_raw("?restarts=1"));
    let state = api.wait_started(&id6)["state"].clone();
    println!("deleting a job that is {state}");
    let (status, events) = runtime().block_on(async {
        let c = async_client();
        let mut s = subscribe(&c, &api.base, None, &id6, None).await;
        let first = next_event(&mut s).await.expect("the snapshot");
        let res = c
            .delete(api.url(&format!("/v1/jobs/{id6}")))
            .send()
            .await
            .expect("DELETE answers");
        let mut events = vec![first];
        events.extend(drain(s).await);
        (res.status(), events)
    });
    assert_eq!(status, StatusCode::NO_CONTENT, "delete a running job");
    let (snapshot, stored) = split_snapshot(&events, &id6);
    assert_eq!(snapshot.data["state"], "running");
    let last = stored.last().expect("events of the deleted job");
    assert_eq!(
        last.event, "failed",
        "the stream ends with `failed`: {last:?}"
    );
    assert_eq!(last.data["state"], "canceled");
    assert!(
        stored.iter().all(|e| e.event != "done"),
        "a deleted job does not succeed"
    );
    let res = send(api.get(&format!("/v1/jobs/{id6}")));
    assert_error(
        res,
        StatusCode::NOT_FOUND,
        "not_found",
        "GET a deleted running job",
    );
    assert!(!api.list("").0.contains(&id6));
    let res = send(api.get("/metrics"));
    assert_eq!(res.status(), StatusCode::OK, "metrics");
    let text = res.text().unwrap();
    assert!(text.contains("monocap_jobs"), "metrics text: {text}");
}

/// With API keys, every /v1 route needs one, and a key sees only its own jobs.
#[test]
fn api_keys_keep_jobs_apart() {
    let mut tokens = Vec::new();
    let svc = Svc::start_with("svc-keys", &[], |data| {
        for name in ["alice", "bob"] {
            let out = monocap(&[
                "keys",
                "create",
                "--name",
                name,
                "--data-dir",
                data.to_str().unwrap(),
            ]);
            assert!(
                out.status.success(),
                "keys create: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            let stdout = String::from_utf8(out.stdout).unwrap();
            let token = stdout
                .lines()
                .last()
                .expect("a token line")
                .trim()
                .to_string();
            assert!(!token.is_empty() && !token.contains(' '), "token {token:?}");
            tokens.push(token);
        }
    });
    assert_ne!(tokens[0], tokens[1]);
    let alice = svc.api(Some(&tokens[0]));
    let bob = svc.api(Some(&tokens[1]));
    let nobody = svc.api(None);
    let wrong = svc.api(Some("mck_not_a_key"));

    // Without a (valid) key.
    for (api, what) in [(&nobody, "no token"), (&wrong, "unknown token")] {
        let res = send(api.get("/v1/jobs"));
        assert_error(res, StatusCode::UNAUTHORIZED, "unauthorized", what);
        let res = send(
            api.post("/v1/jobs")
                .header("content-type", "application/zip")
                .body(fixture()),
        );
        assert_error(res, StatusCode::UNAUTHORIZED, "unauthorized", what);
        let res = send(
            api.post("/v1/probe")
                .header("content-type", "application/zip")
                .body(fixture()),
        );
        assert_error(res, StatusCode::UNAUTHORIZED, "unauthorized", what);
    }
    let res = send(
        nobody
            .get("/v1/jobs")
            .header("authorization", format!("Basic {}", tokens[0])),
    );
    assert_error(
        res,
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        "Basic scheme",
    );
    for path in ["/healthz", "/readyz"] {
        let res = send(nobody.get(path));
        assert_eq!(res.status(), StatusCode::OK, "{path} needs no key");
    }

    let job = alice.raw_upload(
        "?restarts=1",
        "application/zip",
        fixture(),
        Some("same-key"),
    );
    let id = id_of(&accepted(job));
    let res = send(nobody.get(&format!("/v1/jobs/{id}")));
    assert_error(
        res,
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        "a job without a key",
    );
    let done = alice.wait_final(&id);
    assert_eq!(done["state"], "succeeded");

    // Bob sees nothing of Alice's.
    for (m, path, what) in [
        (Method::GET, format!("/v1/jobs/{id}"), "GET"),
        (Method::GET, format!("/v1/jobs/{id}/events"), "events"),
        (
            Method::GET,
            format!("/v1/jobs/{id}/artifacts/motion.bvh"),
            "artifact",
        ),
        (Method::POST, format!("/v1/jobs/{id}/cancel"), "cancel"),
        (Method::POST, format!("/v1/jobs/{id}/rerun"), "rerun"),
        (Method::DELETE, format!("/v1/jobs/{id}"), "delete"),
    ] {
        let res = send(bob.req(m, &path));
        assert_error(
            res,
            StatusCode::NOT_FOUND,
            "not_found",
            &format!("{what} of another key's job"),
        );
    }
    assert_eq!(bob.list("").0, Vec::<String>::new(), "Bob's list is empty");
    assert_eq!(bob.list("?state=succeeded").0, Vec::<String>::new());
    // The same Idempotency-Key from Bob is Bob's own job.
    let bobs = accepted(bob.raw_upload(
        "?restarts=1",
        "application/zip",
        fixture(),
        Some("same-key"),
    ));
    let bob_id = id_of(&bobs);
    assert_ne!(bob_id, id, "idempotency keys are per API key");
    assert_eq!(bob.list("").0, vec![bob_id.clone()]);
    let res = send(alice.get(&format!("/v1/jobs/{bob_id}")));
    assert_error(
        res,
        StatusCode::NOT_FOUND,
        "not_found",
        "Alice reads Bob's job",
    );

    // Alice still has hers, untouched by Bob's attempts.
    let job = alice.job(&id);
    assert_eq!(job["state"], "succeeded");
    assert_eq!(alice.list("").0, vec![id.clone()]);
    assert!(!alice.artifact(&id, "motion.json").is_empty());
    let events = all_events(&alice.base, Some(&tokens[0]), &id, None);
    let (_, stored) = split_snapshot(&events, &id);
    check_success_events(stored, 0..FIXTURE_FRAMES);
    assert_eq!(bob.wait_final(&bob_id)["state"], "succeeded");
}

/// Bad requests of every kind: the right status and error code, and the service
/// goes on.
#[test]
fn bad_requests_get_json_errors_and_the_server_goes_on() {
    let svc = Svc::start("svc-bad", &[]);
    let api = svc.api(None);
    let id = id_of(&api.submit_raw("?restarts=1"));
    let zip = fixture();
    let unprocessable = StatusCode::UNPROCESSABLE_ENTITY;

    let check = |res: Response, status: StatusCode, code: &str, what: &str| {
        assert_error(res, status, code, what);
        api.assert_alive(&id, what);
    };

    // Uploads.
    let raw = |q: &str, ct: &str, body: Vec<u8>| api.raw_upload(q, ct, body, None);
    check(
        raw("", "text/plain", b"hello".to_vec()),
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media",
        "text/plain",
    );
    check(
        send(api.post("/v1/jobs").body(zip.clone())),
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media",
        "no Content-Type",
    );
    check(
        raw("?restarts=1", "application/zip", Vec::new()),
        unprocessable,
        "empty_clip",
        "empty raw body",
    );
    let garbage: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    check(
        raw("?restarts=1", "application/octet-stream", garbage.clone()),
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media",
        "garbage bytes",
    );
    check(
        raw("?restarts=1", "video/mp4", garbage[..100].to_vec()),
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media",
        "garbage as video/mp4",
    );
    let mut truncated_zip = zip.clone();
    truncated_zip.truncate(zip.len() / 2);
    check(
        raw("?restarts=1", "application/zip", truncated_zip),
        unprocessable,
        "unreadable_clip",
        "truncated ZIP",
    );

    let mp = |body: Vec<u8>| {
        send(
            api.post("/v1/jobs")
                .header(
                    "content-type",
                    format!("multipart/form-data; boundary={BOUNDARY}"),
                )
                .body(body),
        )
    };
    // Cut in the middle of the clip part, no closing boundary.
    let whole = multipart_body(&[("clip", Some("a.zip"), &zip)], true);
    check(
        mp(whole[..whole.len() / 2].to_vec()),
        StatusCode::BAD_REQUEST,
        "bad_upload",
        "truncated multipart",
    );
    check(
        send(
            api.post("/v1/jobs")
                .header("content-type", "multipart/form-data")
                .body(whole.clone()),
        ),
        StatusCode::BAD_REQUEST,
        "bad_upload",
        "multipart without a boundary",
    );
    check(
        mp(multipart_body(
            &[("options", None, br#"{"restarts":1}"#)],
            true,
        )),
        unprocessable,
        "bad_upload",
        "multipart without a clip part",
    );
    check(
        mp(multipart_body(
            &[("clip", Some("a.zip"), &zip), ("extra", None, b"x")],
            true,
        )),
        unprocessable,
        "bad_upload",
        "multipart with an unknown part",
    );
    check(
        mp(multipart_body(
            &[("clip", Some("a.zip"), &zip), ("clip", Some("b.zip"), &zip)],
            true,
        )),
        unprocessable,
        "bad_upload",
        "multipart with two clips",
    );
    check(
        mp(multipart_body(&[("clip", Some("a.zip"), b"")], true)),
        unprocessable,
        "empty_clip",
        "multipart with an empty clip",
    );
    for (options, what) in [
        (&b"{not json"[..], "options part not JSON"),
        (&b"[1, 2]"[..], "options part not an object"),
        (&br#"{"restarts": 0}"#[..], "options restarts=0"),
        (&br#"{"colour": "red"}"#[..], "options unknown field"),
        (&br#"{"frames": "9..2"}"#[..], "options empty range"),
        (&br#"{"restarts": "many"}"#[..], "options wrong type"),
    ] {
        check(
            mp(multipart_body(
                &[("clip", Some("a.zip"), &zip), ("options", None, options)],
                true,
            )),
            unprocessable,
            "bad_options",
            what,
        );
    }
    check(
        send(
            api.post("/v1/jobs?restarts=1")
                .header(
                    "content-type",
                    format!("multipart/form-data; boundary={BOUNDARY}"),
                )
                .body(multipart_body(&[("clip", Some("a.zip"), &zip)], true)),
        ),
        unprocessable,
        "bad_options",
        "multipart with query options",
    );
    for (query, what) in [
        ("?colour=red", "unknown option"),
        ("?frames=-3..5", "negative frame range"),
        ("?frames=9..2", "backwards frame range"),
        ("?frames=4..4", "empty frame range"),
        ("?frames=30..40", "frames past the clip"),
        ("?restarts=0", "restarts=0"),
        ("?restarts=21", "restarts=21"),
        ("?restarts=1&restarts=2", "an option twice"),
        ("?init_frame=99", "init_frame past the clip"),
        ("?fov_deg=500", "fov_deg out of range"),
        ("?keyframes=nope", "keyframes not JSON"),
        ("?empty_frames=sometimes", "bad empty_frames"),
        ("?work_height=5", "work_height too small"),
    ] {
        check(
            raw(query, "application/zip", zip.clone()),
            unprocessable,
            "bad_options",
            what,
        );
    }
    for (key, what) in [
        ("x".repeat(201), "a 201-character Idempotency-Key"),
        (String::new(), "an empty Idempotency-Key"),
    ] {
        check(
            api.raw_upload("?restarts=1", "application/zip", zip.clone(), Some(&key)),
            StatusCode::BAD_REQUEST,
            "bad_idempotency_key",
            what,
        );
    }

    // A huge declared length, over raw TCP.
    let answer = raw_http(
        svc.port(),
        b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/zip\r\n\
          Content-Length: 99999999999999\r\nConnection: close\r\n\r\nPK\x03\x04",
    );
    println!("huge Content-Length: {answer:?}");
    assert!(
        answer.starts_with("HTTP/1.1 413"),
        "huge Content-Length: {answer:?}"
    );
    let (head, body) = answer.split_once("\r\n\r\n").expect("a head and a body");
    assert!(
        head.to_ascii_lowercase()
            .contains("content-type: application/json"),
        "{head}"
    );
    let v: Value = serde_json::from_str(body).expect("a JSON error body");
    assert_eq!(v["error"]["code"], "too_large");
    api.assert_alive(&id, "a huge Content-Length");

    // Jobs and routes that do not exist.
    let missing = "01890000-0000-7000-8000-000000000000";
    for (m, path, status, code, what) in [
        (
            Method::GET,
            format!("/v1/jobs/{missing}"),
            404,
            "not_found",
            "unknown job",
        ),
        (
            Method::GET,
            "/v1/jobs/abc".into(),
            404,
            "not_found",
            "malformed id",
        ),
        (
            Method::GET,
            format!("/v1/jobs/{missing}/events"),
            404,
            "not_found",
            "events of an unknown job",
        ),
        (
            Method::GET,
            "/v1/jobs/abc/artifacts/motion.bvh".into(),
            404,
            "not_found",
            "files of a malformed id",
        ),
        (
            Method::POST,
            format!("/v1/jobs/{missing}/cancel"),
            404,
            "not_found",
            "cancel an unknown job",
        ),
        (
            Method::POST,
            format!("/v1/jobs/{missing}/rerun"),
            404,
            "not_found",
            "rerun an unknown job",
        ),
        (
            Method::DELETE,
            format!("/v1/jobs/{missing}"),
            404,
            "not_found",
            "delete an unknown job",
        ),
        (
            Method::GET,
            "/v2/jobs".into(),
            404,
            "not_found",
            "unknown route",
        ),
        (Method::GET, "/".into(), 404, "not_found", "the root"),
        (
            Method::PUT,
            "/v1/jobs".into(),
            405,
            "method_not_allowed",
            "PUT /v1/jobs",
        ),
        (
            Method::PATCH,
            format!("/v1/jobs/{id}"),
            405,
            "method_not_allowed",
            "PATCH a job",
        ),
        (
            Method::GET,
            "/v1/probe".into(),
            405,
            "method_not_allowed",
            "GET probe",
        ),
        (
            Method::POST,
            "/healthz".into(),
            405,
            "method_not_allowed",
            "POST healthz",
        ),
        (
            Method::GET,
            "/v1/jobs?limit=0".into(),
            400,
            "bad_query",
            "limit=0",
        ),
        (
            Method::GET,
            "/v1/jobs?limit=101".into(),
            400,
            "bad_query",
            "limit=101",
        ),
        (
            Method::GET,
            "/v1/jobs?limit=ten".into(),
            400,
            "bad_query",
            "limit=ten",
        ),
        (
            Method::GET,
            "/v1/jobs?state=bogus".into(),
            400,
            "bad_query",
            "state=bogus",
        ),
        (
            Method::GET,
            "/v1/jobs?cursor=xyz".into(),
            400,
            "bad_query",
            "cursor=xyz",
        ),
        (
            Method::GET,
            "/v1/jobs?colour=red".into(),
            400,
            "bad_query",
            "unknown param",
        ),
    ] {
        let res = send(api.req(m, &path));
        check(res, StatusCode::from_u16(status).unwrap(), code, what);
    }

    // Event streams.
    for bad in ["abc", "-1", "1.5", ""] {
        let res = send(
            api.get(&format!("/v1/jobs/{id}/events"))
                .header("last-event-id", bad),
        );
        check(
            res,
            StatusCode::BAD_REQUEST,
            "bad_last_event_id",
            &format!("Last-Event-ID {bad:?}"),
        );
    }

    // Ranges of a finished job's file.
    assert_eq!(api.wait_final(&id)["state"], "succeeded");
    let size = api.artifact(&id, "motion.bvh").len();
    for range in [
        format!("bytes={size}-"),
        format!("bytes={}-{}", size + 10, size + 20),
        "bytes=50-10".to_string(),
        "bytes=-0".to_string(),
    ] {
        let res = send(
            api.get(&format!("/v1/jobs/{id}/artifacts/motion.bvh"))
                .header("range", &range),
        );
        let content_range = header(&res, "content-range");
        assert_eq!(
            content_range,
            Some(format!("bytes */{size}")),
            "416 names the size"
        );
        check(res, StatusCode::RANGE_NOT_SATISFIABLE, "bad_range", &range);
    }
    // Cancel of the finished job.
    check(
        send(api.post(&format!("/v1/jobs/{id}/cancel"))),
        StatusCode::CONFLICT,
        "already_finished",
        "cancel a finished job",
    );

    // After all that, a good upload still works.
    let id2 = id_of(&api.submit_multipart(r#"{"restarts": 1, "frames": "0..4"}"#));
    assert_eq!(api.wait_final(&id2)["state"], "succeeded");
    assert_eq!(
        frame_indices(&api.motion_json(&id2)),
        (0..4).collect::<Vec<_>>()
    );
}

/// `--max-upload-mb 1`: larger uploads are refused with 413, whichever way they come.
/// (The big uploads go through the async client, which returns a response that comes
/// before the whole body was sent; the blocking client reports the body error instead.)
#[test]
fn uploads_over_the_limit_are_refused() {
    let svc = Svc::start("svc-limit", &["--max-upload-mb", "1"]);
    let api = svc.api(None);
    let id = id_of(&api.submit_raw("?restarts=1"));
    let mut big = fixture();
    big.resize(2 << 20, 0);
    // Within the slack allowed for the declared length, so the stream itself is
    // counted against the limit.
    let mut over = fixture();
    over.resize((1 << 20) + (100 << 10), 0);
    let mp_ct = format!("multipart/form-data; boundary={BOUNDARY}");
    let cases: Vec<(&str, &str, String, Vec<u8>, bool)> = vec![
        (
            "2 MiB raw body",
            "/v1/jobs?restarts=1",
            "application/zip".into(),
            big.clone(),
            false,
        ),
        (
            "1.1 MiB raw body",
            "/v1/jobs?restarts=1",
            "application/zip".into(),
            over.clone(),
            false,
        ),
        (
            "2 MiB chunked",
            "/v1/jobs?restarts=1",
            "application/zip".into(),
            big.clone(),
            true,
        ),
        (
            "1.1 MiB chunked",
            "/v1/jobs?restarts=1",
            "video/mp4".into(),
            over.clone(),
            true,
        ),
        (
            "2 MiB multipart",
            "/v1/jobs",
            mp_ct.clone(),
            multipart_body(&[("clip", Some("big.zip"), &big)], true),
            false,
        ),
        (
            "1.1 MiB multipart",
            "/v1/jobs",
            mp_ct.clone(),
            multipart_body(&[("clip", Some("big.zip"), &over)], true),
            false,
        ),
        (
            "2 MiB multipart, chunked",
            "/v1/jobs",
            mp_ct,
            multipart_body(&[("clip", Some("big.zip"), &big)], true),
            true,
        ),
        (
            "2 MiB probe",
            "/v1/probe",
            "application/zip".into(),
            big.clone(),
            false,
        ),
        (
            "1.1 MiB probe, chunked",
            "/v1/probe",
            "application/zip".into(),
            over,
            true,
        ),
    ];
    let rt = runtime();
    let c = async_client();
    for (what, path, ct, body, chunked) in cases {
        let (status, content_type, text) =
            rt.block_on(upload_async(&c, &api.url(path), &ct, body, chunked));
        check_error_parts(
            status,
            &content_type,
            &text,
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_large",
            what,
        );
        api.assert_alive(&id, what);
    }

    // Nothing half-received is kept, and a small upload still works.
    assert_eq!(api.list("").0, vec![id.clone()]);
    let id2 = id_of(&api.submit_raw("?restarts=1"));
    assert_eq!(api.wait_final(&id)["state"], "succeeded");
    assert_eq!(api.wait_final(&id2)["state"], "succeeded");
    let uploads = svc.dir.path("data").join("uploads");
    let left: Vec<_> = std::fs::read_dir(&uploads)
        .map(|d| d.filter_map(Result::ok).map(|e| e.file_name()).collect())
        .unwrap_or_default();
    assert!(left.is_empty(), "upload scratch files left: {left:?}");
}

/// POSTs `body` with the async client, with a declared length or chunked; returns
/// the status, Content-Type and body text.
async fn upload_async(
    c: &reqwest::Client,
    url: &str,
    content_type: &str,
    body: Vec<u8>,
    chunked: bool,
) -> (StatusCode, String, String) {
    let body = if chunked {
        let chunks: Vec<Result<Vec<u8>, std::io::Error>> =
            body.chunks(64 << 10).map(|c| Ok(c.to_vec())).collect();
        reqwest::Body::wrap_stream(futures_util::stream::iter(chunks))
    } else {
        reqwest::Body::from(body)
    };
    let res = tokio::time::timeout(
        Duration::from_secs(60),
        c.post(url)
            .header("content-type", content_type)
            .body(body)
            .send(),
    )
    .await
    .expect("an answer within 60 s")
    .unwrap_or_else(|e| panic!("POST {url}: no answer: {e:?}"));
    let status = res.status();
    let ct = res
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let text = res.text().await.expect("body");
    (status, ct, text)
}

/// `--max-queue 1 --workers 1`: submissions past a full queue get 429 with
/// Retry-After; the queue drains and takes work again.
#[test]
fn a_full_queue_answers_429() {
    let svc = Svc::start("svc-queue", &["--max-queue", "1", "--workers", "1"]);
    let api = svc.api(None);
    let mut accepted_ids = Vec::new();
    let mut refused = None;
    for i in 0..6 {
        let key = format!("queue-{i}");
        let res = api.raw_upload("?restarts=1", "application/zip", fixture(), Some(&key));
        if res.status() == StatusCode::TOO_MANY_REQUESTS {
            refused = Some(res);
            break;
        }
        accepted_ids.push(id_of(&accepted(res)));
    }
    let res = refused.expect("a submission is refused once the queue is full");
    println!("accepted {} before the 429", accepted_ids.len());
    assert!(!accepted_ids.is_empty() && accepted_ids.len() <= 2);
    let retry: u64 = header(&res, "retry-after")
        .expect("429 has Retry-After")
        .parse()
        .expect("Retry-After in seconds");
    assert!(retry > 0);
    assert_error(
        res,
        StatusCode::TOO_MANY_REQUESTS,
        "queue_full",
        "full queue",
    );
    api.assert_alive(&accepted_ids[0], "a full queue");
    // A rerun counts against the queue too (the queued job is still waiting).
    let waiting = api.list("?state=queued").0;
    if !waiting.is_empty() {
        let res = send(api.post(&format!("/v1/jobs/{}/rerun", accepted_ids[0])));
        if res.status() == StatusCode::ACCEPTED {
            // The worker took the waiting job between the listing and the rerun:
            // then the rerun must have found the queue empty, and the job it waited
            // behind must be out of the queue.
            let rerun = json_body(res);
            assert_eq!(rerun["queue_position"], 0, "rerun, drained queue: {rerun}");
            let state = api.job(&waiting[0])["state"].clone();
            assert_ne!(state, "queued", "rerun accepted with a job still queued");
            println!("the queue drained between the listing and the rerun: accepted");
        } else {
            assert_error(
                res,
                StatusCode::TOO_MANY_REQUESTS,
                "queue_full",
                "rerun, full queue",
            );
        }
    } else {
        println!("the queue drained before the rerun check; skipped it");
    }
    // A retry of an accepted upload (same Idempotency-Key) is answered even now.
    let res = api.raw_upload("?restarts=1", "application/zip", fixture(), Some("queue-0"));
    assert_eq!(id_of(&accepted(res)), accepted_ids[0], "idempotent retry");
    for id in &accepted_ids {
        assert_eq!(api.wait_final(id)["state"], "succeeded");
    }
    let id = id_of(&api.submit_raw("?restarts=1"));
    assert_eq!(api.wait_final(&id)["state"], "succeeded");
}

/// Without API keys the service runs only on a loopback address: on a public one it
/// refuses to start, naming the way out; with a key it starts there.
#[test]
fn without_keys_the_service_stays_on_loopback() {
    let dir = TempDir::new("svc-open");
    let data = dir.path("data");
    let out = monocap(&[
        "serve",
        "--listen",
        "0.0.0.0:0",
        "--data-dir",
        data.to_str().unwrap(),
    ]);
    assert!(
        !out.status.success(),
        "an open server on 0.0.0.0 must not start"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("without API keys") && err.contains("keys create"),
        "stderr: {err}"
    );
    let key = monocap(&[
        "keys",
        "create",
        "--name",
        "ops",
        "--data-dir",
        data.to_str().unwrap(),
    ]);
    assert!(key.status.success());
    let token = String::from_utf8(key.stdout)
        .unwrap()
        .lines()
        .last()
        .unwrap()
        .to_string();
    // With a key it starts on the public address, and requests need the key.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_monocap"))
        .args([
            "serve",
            "--listen",
            "0.0.0.0:0",
            "--data-dir",
            data.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("monocap serve starts");
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let port = line
        .strip_prefix("monocap: listening on http://0.0.0.0:")
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string();
    let url = format!("http://127.0.0.1:{port}/v1/jobs");
    let without = server::client().get(&url).send().map(|r| r.status());
    let with = server::client()
        .get(&url)
        .bearer_auth(&token)
        .send()
        .map(|r| r.status());
    let _ = child.kill();
    let _ = child.wait();
    assert_eq!(
        without.expect("GET jobs"),
        401,
        "with a key configured, requests need it"
    );
    assert_eq!(with.expect("GET jobs"), 200);
}

/// The same service on PostgreSQL (`--database-url`), when a server is given in
/// `MONOCAP_TEST_DATABASE_URL`: a job runs, streams every frame and serves its
/// files; the schema is one of its own, dropped afterwards.
#[test]
fn a_job_runs_on_postgres() {
    let Ok(base) = std::env::var("MONOCAP_TEST_DATABASE_URL") else {
        println!(
            "skipped: MONOCAP_TEST_DATABASE_URL is not set (a PostgreSQL server to test against)"
        );
        return;
    };
    let schema = format!("monocap_svc_{}", uuid::Uuid::now_v7().simple());
    let rt = runtime();
    let admin = rt
        .block_on(sqlx::PgPool::connect(&base))
        .expect("connect to PostgreSQL");
    let ddl = |sql: String| {
        rt.block_on(sqlx::query(sqlx::AssertSqlSafe(sql)).execute(&admin))
            .expect("schema statement");
    };
    ddl(format!("CREATE SCHEMA {schema}"));
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options=-c%20search_path%3D{schema}");
    let outcome = std::panic::catch_unwind(|| {
        let svc = Svc::start("svc-pg", &["--database-url", &url]);
        let api = svc.api(None);
        let id = id_of(&api.submit_raw("?restarts=1"));
        let events = all_events(&api.base, None, &id, None);
        let (_, stored) = split_snapshot(&events, &id);
        check_success_events(stored, 0..FIXTURE_FRAMES);
        let bvh = send(api.get(&format!("/v1/jobs/{id}/artifacts/motion.bvh")));
        assert_eq!(bvh.status(), StatusCode::OK);
        assert_eq!(bvh_frames(&bvh.bytes().unwrap()), FIXTURE_FRAMES as usize);
        // Nothing of it is in the data folder's SQLite file.
        assert!(!svc.dir.path("data").join("monocap.db").exists());
    });
    ddl(format!("DROP SCHEMA {schema} CASCADE"));
    if let Err(e) = outcome {
        std::panic::resume_unwind(e);
    }
}

/// A person who never moves in a clip with no person-free frames is taken for the
/// scene: the job fails, and its error says why and what to do.
#[test]
fn a_still_person_fails_with_the_reason() {
    let dir = TempDir::new("svc-still");
    let still = common::still_person_clip(&dir.path("moving.zip"));

    let svc = Svc::start("svc-still", &[]);
    let api = svc.api(None);
    let id = id_of(&accepted(api.raw_upload(
        "?restarts=1",
        "application/zip",
        still,
        None,
    )));
    let done = api.wait_final(&id);
    assert_eq!(done["state"], "failed", "{done}");
    assert_eq!(done["error"]["code"], "tracking_failed", "{done}");
    let message = done["error"]["message"].as_str().unwrap_or_default();
    assert!(
        message.contains("no person found") && message.contains("person-free frames"),
        "{message}"
    );
}

/// A rerun takes options only: a huge body is refused with the JSON error, not read
/// into memory.
#[test]
fn a_rerun_body_is_small() {
    let svc = Svc::start("svc-rerun-cap", &[]);
    let api = svc.api(None);
    let id = id_of(&api.submit_raw("?restarts=1"));
    let big = vec![b' '; 1 << 20];
    let res = send(
        api.post(&format!("/v1/jobs/{id}/rerun"))
            .header("content-type", "application/json")
            .body(big),
    );
    assert_error(
        res,
        StatusCode::PAYLOAD_TOO_LARGE,
        "too_large",
        "a 1 MiB rerun body",
    );
    assert_eq!(send(api.get("/healthz")).status(), StatusCode::OK);
}
