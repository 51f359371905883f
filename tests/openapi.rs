//! `openapi.yaml` (repository root) against the service: the documented routes are
//! exactly `monocap::api::ROUTES`, each of them is really routed by the running
//! server (and answers with a status the document lists), and every error code the
//! API's source can answer with is listed in the document.
//!
//! No YAML parser is a dependency: the document is read line by line, which works
//! because it is hand-written with two-space indentation (paths at 2 spaces under
//! `paths:`, methods at 4, status codes at 8).

mod common;
#[path = "common/server.rs"]
mod server;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use common::TempDir;
use server::{client, Server};

const METHODS: [&str; 8] = [
    "get", "put", "post", "delete", "options", "head", "patch", "trace",
];

fn read(rel: &str) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("read {}: {e}", p.display()))
}

fn openapi() -> String {
    read("openapi.yaml")
}

/// The lines of the top-level section `key:` (up to the next top-level key).
fn section<'a>(doc: &'a str, key: &str) -> Vec<&'a str> {
    let head = format!("{key}:");
    let mut lines = doc.lines().skip_while(|l| l.trim_end() != head);
    assert!(
        lines.next().is_some(),
        "openapi.yaml has no top-level `{head}`"
    );
    lines
        .take_while(|l| l.is_empty() || l.starts_with(' ') || l.starts_with('#'))
        .collect()
}

/// `key:` at exactly `indent` spaces (quotes around the key allowed), else None.
fn key_at(line: &str, indent: usize) -> Option<&str> {
    let rest = line.strip_prefix(&" ".repeat(indent))?;
    if rest.starts_with(' ') {
        return None;
    }
    let key = rest.trim_end().strip_suffix(':')?;
    let key = key
        .strip_prefix('"')
        .and_then(|k| k.strip_suffix('"'))
        .or_else(|| key.strip_prefix('\'').and_then(|k| k.strip_suffix('\'')))
        .unwrap_or(key);
    Some(key)
}

/// Every operation under `paths:` with the response status codes it lists.
fn operations(doc: &str) -> BTreeMap<(String, String), BTreeSet<String>> {
    let mut ops = BTreeMap::new();
    let mut path: Option<String> = None;
    let mut op: Option<(String, String)> = None;
    for line in section(doc, "paths") {
        if line.trim_start().starts_with('#') {
            continue;
        }
        if let Some(p) = key_at(line, 2) {
            assert!(
                p.starts_with('/'),
                "a key under paths: that is no path: {line:?}"
            );
            path = Some(p.to_string());
            op = None;
            continue;
        }
        if let Some(m) = key_at(line, 4) {
            op = None;
            if METHODS.contains(&m) {
                let p = path.clone().expect("a method before any path");
                let k = (m.to_string(), p);
                assert!(!ops.contains_key(&k), "{k:?} twice in openapi.yaml");
                ops.insert(k.clone(), BTreeSet::new());
                op = Some(k);
            }
            continue;
        }
        // Status codes are the keys at 8 spaces under an operation's `responses:`.
        if let (Some(k), Some(code)) = (&op, key_at(line, 8)) {
            if code.len() == 3 && code.bytes().all(|b| b.is_ascii_digit()) {
                ops.get_mut(k).unwrap().insert(code.to_string());
            }
        }
    }
    ops
}

/// The items of the `enum:` list of the schema `name` in components/schemas.
fn schema_enum(doc: &str, name: &str) -> BTreeSet<String> {
    let lines = section(doc, "components");
    let head = format!("    {name}:");
    let start = lines
        .iter()
        .position(|l| l.trim_end() == head)
        .unwrap_or_else(|| panic!("openapi.yaml has no schema {name}"));
    let body: Vec<&str> = lines[start + 1..]
        .iter()
        .take_while(|l| l.is_empty() || l.starts_with("      "))
        .copied()
        .collect();
    let at = body
        .iter()
        .position(|l| l.trim_end() == "      enum:")
        .unwrap_or_else(|| panic!("schema {name} has no block `enum:` list"));
    body[at + 1..]
        .iter()
        .map_while(|l| l.trim().strip_prefix("- "))
        .map(|v| v.trim().trim_matches('"').to_string())
        .collect()
}

fn routes() -> BTreeSet<(String, String)> {
    let routes: BTreeSet<(String, String)> = monocap::api::ROUTES
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(
        routes.len(),
        monocap::api::ROUTES.len(),
        "ROUTES repeats a route"
    );
    routes
}

#[test]
fn the_document_lists_exactly_the_routes() {
    let doc = openapi();
    assert!(doc.starts_with("openapi: 3.1"), "an OpenAPI 3.1 document");
    let documented: BTreeSet<(String, String)> = operations(&doc).into_keys().collect();
    let routed = routes();
    let missing: Vec<_> = routed.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&routed).collect();
    assert!(
        missing.is_empty(),
        "routes in monocap::api::ROUTES that openapi.yaml does not describe: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "operations in openapi.yaml that are not in monocap::api::ROUTES: {extra:?}"
    );
    for (op, codes) in operations(&doc) {
        assert!(!codes.is_empty(), "{op:?} lists no responses");
    }
    // The pieces the routes refer to.
    for needle in [
        "securitySchemes:",
        "scheme: bearer",
        "name: Idempotency-Key",
        "name: Last-Event-ID",
        "name: If-None-Match",
        "name: Range",
        "multipart/form-data:",
        "text/event-stream:",
    ] {
        assert!(doc.contains(needle), "openapi.yaml lacks {needle:?}");
    }
    for schema in ["Job", "JobList", "Error", "Probe", "JobOptions"] {
        assert!(
            doc.contains(&format!("\n    {schema}:\n")),
            "openapi.yaml has no schema {schema}"
        );
    }
    for kind in ["`state`", "`progress`", "`done`", "`failed`"] {
        assert!(doc.contains(kind), "the event kind {kind} is not described");
    }
}

/// The arguments of the call whose `(` is at `open` (text up to its `)`), split at
/// top-level commas; string literals and nested brackets are skipped over.
fn call_args(src: &str, open: usize) -> Vec<String> {
    let bytes = src.as_bytes();
    assert_eq!(bytes[open], b'(');
    let (mut depth, mut i, mut start) = (0usize, open, open + 1);
    let mut args = Vec::new();
    while i < bytes.len() {
        match bytes[i] {
            b'"' => {
                i += 1;
                while i < bytes.len() && bytes[i] != b'"' {
                    if bytes[i] == b'\\' {
                        i += 1;
                    }
                    i += 1;
                }
            }
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' => {
                depth -= 1;
                if depth == 0 {
                    args.push(src[start..i].trim().to_string());
                    return args;
                }
            }
            b',' if depth == 1 => {
                args.push(src[start..i].trim().to_string());
                start = i + 1;
            }
            _ => {}
        }
        i += 1;
    }
    panic!("unclosed call at byte {open}");
}

/// A plain string literal `"abc"`, unquoted.
fn literal(arg: &str) -> Option<String> {
    let inner = arg.strip_prefix('"')?.strip_suffix('"')?;
    (!inner.contains('"') && !inner.contains('\\')).then(|| inner.to_string())
}

/// The codes passed as literals to `call` (argument `index`) in `src`.
fn codes_in(src: &str, call: &str, index: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(at) = src[from..].find(call) {
        let open = from + at + call.len() - 1;
        from = open + 1;
        // `fn bad_request(` is the definition, not a call.
        if src[..open - call.len() + 1].trim_end().ends_with("fn") {
            continue;
        }
        if let Some(code) = call_args(src, open).get(index).and_then(|a| literal(a)) {
            out.push(code);
        }
    }
    out
}

/// Every error code the API's source answers with.
fn source_codes() -> BTreeSet<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/api");
    let mut codes = BTreeSet::new();
    let mut files = 0;
    for entry in std::fs::read_dir(&dir).expect("list src/api") {
        let path = entry.expect("dir entry").path();
        if path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        files += 1;
        let src = std::fs::read_to_string(&path).expect("read source");
        codes.extend(codes_in(&src, "ApiError::new(", 1));
        codes.extend(codes_in(&src, "bad_request(", 0));
        codes.extend(codes_in(&src, "unprocessable(", 0));
        if src.contains("ApiError::not_found(") {
            codes.insert("not_found".into());
        }
        if src.contains("ApiError::internal") {
            codes.insert("internal".into());
        }
        // Framework rejections mapped to codes: `StatusCode::X => "code",`.
        for line in src.lines() {
            if let Some((lhs, rhs)) = line.split_once("=> ") {
                if lhs.trim().starts_with("StatusCode::") || lhs.trim() == "_" {
                    if let Some(code) = literal(rhs.trim().trim_end_matches(',')) {
                        codes.insert(code);
                    }
                }
            }
        }
    }
    assert!(files >= 5, "found only {files} files in {}", dir.display());
    codes
}

#[test]
fn the_source_scan_finds_codes() {
    let src = r#"
        fn bad_request(code: &'static str) -> ApiError { ApiError::new(StatusCode::BAD_REQUEST, code, m) }
        let a = ApiError::new(
            StatusCode::CONFLICT,
            "already_finished",
            format!("job {id} has already ended ({})", job.state.as_str()),
        );
        ApiError::bad_request("bad_query", format!("x, y"));
        ApiError::unprocessable("bad_options", e);
    "#;
    assert_eq!(codes_in(src, "ApiError::new(", 1), ["already_finished"]);
    assert_eq!(codes_in(src, "bad_request(", 0), ["bad_query"]);
    assert_eq!(codes_in(src, "unprocessable(", 0), ["bad_options"]);
}

#[test]
fn the_document_lists_every_error_code() {
    let doc = openapi();
    let listed = schema_enum(&doc, "ErrorCode");
    let used = source_codes();
    // A sanity check of the scan itself.
    for code in [
        "not_found",
        "unauthorized",
        "bad_options",
        "queue_full",
        "too_large",
    ] {
        assert!(
            used.contains(code),
            "the source scan missed {code}: {used:?}"
        );
    }
    let missing: Vec<_> = used.difference(&listed).collect();
    assert!(
        missing.is_empty(),
        "error codes in src/api that openapi.yaml's ErrorCode does not list: {missing:?}"
    );
    let stale: Vec<_> = listed.difference(&used).collect();
    assert!(
        stale.is_empty(),
        "ErrorCode lists codes src/api never answers with: {stale:?}"
    );
    for code in &listed {
        assert!(
            doc.contains(&format!("`{code}`")),
            "the error code {code} is not described anywhere in openapi.yaml"
        );
    }

    // Job error codes: what the worker fails a job with, and recovery's `gave_up`.
    let job_codes = schema_enum(&doc, "JobErrorCode");
    let worker = read("src/jobs/worker.rs");
    let mut made: BTreeSet<String> = codes_in(&worker, "Failure::new(", 0).into_iter().collect();
    for code in ["canceled", "time_limit", "gave_up"] {
        made.insert(code.to_string());
    }
    let missing: Vec<_> = made.difference(&job_codes).collect();
    assert!(
        missing.is_empty(),
        "job error codes openapi.yaml's JobErrorCode does not list: {missing:?}"
    );
}

/// A documented path with its placeholders filled.
fn concrete(path: &str) -> String {
    path.replace("{id}", "0190a3c4-5b6d-7e8f-9a0b-1c2d3e4f5a6b")
        .replace("{name}", "motion.bvh")
}

/// Whether the answer is the router's fallback (no route, or no such method).
fn is_fallback(status: u16, body: &serde_json::Value) -> bool {
    let code = body["error"]["code"].as_str().unwrap_or("");
    let message = body["error"]["message"].as_str().unwrap_or("");
    (status == 404 && message.starts_with("no such route")) || code == "method_not_allowed"
}

#[test]
fn every_documented_route_is_routed() {
    let doc = openapi();
    let ops = operations(&doc);
    let dir = TempDir::new("openapi");
    let srv = Server::start(&dir.path("data"), &[]);
    let http = client();
    let send = |method: &str, path: &str| {
        let m = reqwest::Method::from_bytes(method.to_ascii_uppercase().as_bytes()).unwrap();
        let res = http.request(m, srv.at(path)).send().expect("request");
        let status = res.status().as_u16();
        let text = res.text().unwrap_or_default();
        let body = serde_json::from_str(&text).unwrap_or(serde_json::Value::Null);
        (status, body, text)
    };

    // The detector works: an unknown path and a wrong method are the fallback.
    let (status, body, _) = send("get", "/v1/nothing-here");
    assert!(is_fallback(status, &body), "{status} {body}");
    let (status, body, _) = send("put", "/v1/jobs");
    assert_eq!(status, 405);
    assert!(is_fallback(status, &body), "{status} {body}");

    for ((method, path), statuses) in &ops {
        let url = concrete(path);
        let (status, body, text) = send(method, &url);
        assert!(
            !is_fallback(status, &body),
            "{} {url} (documented as {path}) is not routed: {status} {text}",
            method.to_uppercase()
        );
        assert!(
            statuses.contains(&status.to_string()),
            "{} {url} answered {status}, which openapi.yaml does not list for it ({statuses:?}): {text}",
            method.to_uppercase()
        );
        if status >= 400 {
            let code = body["error"]["code"].as_str();
            assert!(
                code.is_some(),
                "{} {url}: a {status} without the error body: {text}",
                method.to_uppercase()
            );
        }
    }

    // A path that does not decode is a documented 400 with the error body too, not
    // the framework's plain text.
    let codes = schema_enum(&doc, "ErrorCode");
    for ((method, path), statuses) in ops.iter().filter(|((_, p), _)| p.contains("{id}")) {
        let url = concrete(path).replace("0190a3c4-5b6d-7e8f-9a0b-1c2d3e4f5a6b", "%FF");
        let (status, body, text) = send(method, &url);
        let m = method.to_uppercase();
        assert_eq!(status, 400, "{m} {url}: {text}");
        assert!(statuses.contains("400"), "{m} {path} does not list 400");
        let code = body["error"]["code"].as_str().unwrap_or_else(|| {
            panic!("{m} {url}: a 400 without the error body: {text}");
        });
        assert!(codes.contains(code), "{m} {url}: undocumented code {code}");
    }
}

#[test]
fn documented_option_limits_are_the_services() {
    use monocap::jobs::options::JobOptions;
    let check = |json: serde_json::Value, ok: bool| {
        let res = JobOptions::from_json(json.clone()).and_then(|o| o.to_track().map(|_| ()));
        assert_eq!(res.is_ok(), ok, "{json}: {res:?}");
    };
    let doc = openapi();
    // fov_deg: (1, 170) exclusive, the camera's own rule (a wider one was accepted
    // and then failed the job).
    assert!(doc.contains("exclusiveMaximum: 170"));
    check(serde_json::json!({"fov_deg": 169.5}), true);
    check(serde_json::json!({"fov_deg": 170.0}), false);
    check(serde_json::json!({"fov_deg": 175.0}), false);
    check(serde_json::json!({"fov_deg": 1.0}), false);
    check(serde_json::json!({"restarts": 20}), true);
    check(serde_json::json!({"restarts": 21}), false);
    check(serde_json::json!({"restarts": 0}), false);
    check(serde_json::json!({"polish_evals": 0}), true);
    check(serde_json::json!({"polish_evals": 10000}), true);
    check(serde_json::json!({"polish_evals": 10001}), false);
    check(serde_json::json!({"polish_evals": -1}), false);
    check(serde_json::json!({"refit_sigma": 0.0}), true);
    check(serde_json::json!({"refit_sigma": 10.0}), true);
    check(serde_json::json!({"refit_sigma": 10.5}), false);
    check(serde_json::json!({"refit_sigma": -1.0}), false);
    check(serde_json::json!({"refit_runs": 20}), true);
    check(serde_json::json!({"refit_runs": 0}), false);
    check(serde_json::json!({"refit_runs": 21}), false);
    check(serde_json::json!({"refit_again_iou": 0.0}), true);
    check(serde_json::json!({"refit_again_iou": 1.0}), true);
    check(serde_json::json!({"refit_again_iou": 1.5}), false);
    check(serde_json::json!({"refit_again_iou": -0.1}), false);
    check(serde_json::json!({"refit_anchor": 0.0}), true);
    check(serde_json::json!({"refit_anchor": 10000.0}), true);
    check(serde_json::json!({"refit_anchor": 10000.5}), false);
    check(serde_json::json!({"refit_anchor": -1.0}), false);
    check(serde_json::json!({"refit_rounds": 1}), true);
    check(serde_json::json!({"refit_rounds": 4}), true);
    check(serde_json::json!({"refit_rounds": 0}), false);
    check(serde_json::json!({"refit_rounds": 5}), false);
    check(serde_json::json!({"switch_penalty": 0.0}), true);
    check(serde_json::json!({"switch_penalty": 1000.0}), true);
    check(serde_json::json!({"switch_penalty": 1000.5}), false);
    check(serde_json::json!({"switch_penalty": -0.01}), false);
    check(serde_json::json!({"middle_starts": 1}), true);
    check(serde_json::json!({"middle_starts": 4}), true);
    check(serde_json::json!({"middle_starts": 0}), false);
    check(serde_json::json!({"middle_starts": 5}), false);
    check(serde_json::json!({"middle_starts": 1.5}), false);
    assert!(doc.contains("name: middle_starts"));
    let query = JobOptions::from_query(&[("middle_starts".into(), "3".into())]).unwrap();
    assert_eq!(query.to_track().unwrap().track.middle_starts, 3);
    assert_eq!(
        JobOptions::default()
            .to_track()
            .unwrap()
            .track
            .middle_starts,
        1
    );
    check(serde_json::json!({"parted_middle_starts": 0}), true);
    check(serde_json::json!({"parted_middle_starts": 4}), true);
    check(serde_json::json!({"parted_middle_starts": 5}), false);
    check(serde_json::json!({"parted_middle_starts": -1}), false);
    assert!(doc.contains("name: parted_middle_starts"));
    let query = JobOptions::from_query(&[("parted_middle_starts".into(), "3".into())]).unwrap();
    assert_eq!(query.to_track().unwrap().track.parted_middle_starts, 3);
    assert_eq!(
        JobOptions::default()
            .to_track()
            .unwrap()
            .track
            .parted_middle_starts,
        monocap::track::tracker::TrackOptions::default().parted_middle_starts
    );
    assert!(doc.contains("name: switch_penalty"));
    let query = JobOptions::from_query(&[("switch_penalty".into(), "0".into())]).unwrap();
    assert_eq!(query.to_track().unwrap().track.switch_penalty, 0.0);
    let default = JobOptions::default().to_track().unwrap().track;
    assert_eq!(
        default.switch_penalty,
        monocap::track::tracker::SWITCH_PENALTY
    );
    // The passes after the first and the second start: booleans, on by default,
    // off from a query too.
    type On = fn(&monocap::track::tracker::TrackOptions) -> bool;
    let passes: [(&str, On); 5] = [
        ("two_way", |t| t.two_way),
        ("middle_pass", |t| t.middle_pass),
        ("round_start", |t| t.round_start),
        ("exemplar_starts", |t| t.exemplar_starts),
        ("mirror_starts", |t| t.mirror_starts),
    ];
    for (name, on) in passes {
        check(serde_json::json!({ name: true }), true);
        check(serde_json::json!({ name: false }), true);
        check(serde_json::json!({ name: "yes" }), false);
        check(serde_json::json!({ name: 0 }), false);
        let off = JobOptions::from_query(&[(name.into(), "false".into())]).unwrap();
        assert!(
            !on(&off.to_track().unwrap().track),
            "{name}=false in a query"
        );
        let default = JobOptions::default().to_track().unwrap();
        assert!(on(&default.track), "{name} on by default");
    }
    check(serde_json::json!({"work_height": 32}), true);
    check(serde_json::json!({"work_height": 1080}), true);
    check(serde_json::json!({"work_height": 1081}), false);
    check(serde_json::json!({"w_edge": -1.0}), false);
    check(serde_json::json!({"reward_rim": 2.0}), true);
    check(serde_json::json!({"reward_rim": -0.5}), false);
    check(serde_json::json!({"extremity_reach": 0.05}), true);
    check(serde_json::json!({"extremity_reach": 1.0}), true);
    check(serde_json::json!({"extremity_reach": 1.5}), false);
    check(serde_json::json!({"extremity_reach": -0.1}), false);
    // The elbows' and knees' claims: on by default, off from a query.
    check(serde_json::json!({"claim_reach": 0.0}), true);
    check(serde_json::json!({"claim_reach": 1.0}), true);
    check(serde_json::json!({"claim_reach": 1.5}), false);
    check(serde_json::json!({"claim_reach": -0.1}), false);
    let off = JobOptions::from_query(&[("claim_reach".into(), "0".into())]).unwrap();
    assert_eq!(off.to_track().unwrap().track.weights.claim_reach, 0.0);
    assert_eq!(
        JobOptions::default()
            .to_track()
            .unwrap()
            .track
            .weights
            .claim_reach,
        monocap::track::objective::CLAIM_REACH
    );
    check(serde_json::json!({"track_rewards": true}), true);
    check(serde_json::json!({"track_rewards": 1}), false);
    // The shared ends: off by default, on from a query.
    check(serde_json::json!({"shared_ends": true}), true);
    check(serde_json::json!({"shared_ends": "no"}), false);
    let shared = JobOptions::from_query(&[("shared_ends".into(), "true".into())]).unwrap();
    assert!(shared.to_track().unwrap().track.weights.shared_ends);
    assert!(
        !JobOptions::default()
            .to_track()
            .unwrap()
            .track
            .weights
            .shared_ends
    );
    // The full probes: off by default, on from a query.
    check(serde_json::json!({"full_probes": true}), true);
    check(serde_json::json!({"full_probes": "yes"}), false);
    let full = JobOptions::from_query(&[("full_probes".into(), "true".into())]).unwrap();
    assert!(full.to_track().unwrap().track.full_probes);
    assert!(!JobOptions::default().to_track().unwrap().track.full_probes);
    // The mirror jumps: off by default, on from a query.
    check(serde_json::json!({"mirror_jumps": true}), true);
    check(serde_json::json!({"mirror_jumps": "yes"}), false);
    let mirror = JobOptions::from_query(&[("mirror_jumps".into(), "true".into())]).unwrap();
    assert!(mirror.to_track().unwrap().track.mirror_jumps);
    assert!(!JobOptions::default().to_track().unwrap().track.mirror_jumps);
    check(serde_json::json!({"no_such_option": 1}), false);
}
