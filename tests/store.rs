//! The job store's contract, run against SQLite (always) and PostgreSQL (when
//! `MONOCAP_TEST_DATABASE_URL` is set; each run in a schema of its own, dropped
//! afterwards).

mod common;

use monocap::store::sql::SqlStore;
use monocap::store::{
    Artifact, Event, Inserted, JobError, JobFilter, JobState, NewJob, Outcome, ProgressRow, Store,
};
use serde_json::json;

fn new_job(id: &str, owner: &str, key: Option<&str>) -> NewJob {
    NewJob {
        id: id.into(),
        owner: owner.into(),
        options: json!({ "restarts": 1 }),
        clip_key: format!("clips/{id}"),
        clip_name: "run.zip".into(),
        clip_bytes: 1234,
        clip_info: json!({ "container": "zip", "frame_count": 23 }),
        idempotency_key: key.map(String::from),
        rerun_of: None,
    }
}

fn ev(seq: i64, kind: &str) -> Event {
    Event {
        seq,
        kind: kind.into(),
        data: json!({ "n": seq }),
    }
}

/// Ids in creation order (UUIDv7 sorts by time).
fn ids(n: usize) -> Vec<String> {
    (0..n)
        .map(|_| {
            std::thread::sleep(std::time::Duration::from_millis(2));
            uuid::Uuid::now_v7().to_string()
        })
        .collect()
}

async fn contract(store: &dyn Store) {
    let id = ids(4);
    // Insert, and idempotency per owner.
    let Inserted::New(a) = store
        .insert_job(new_job(&id[0], "k1", Some("take-7")))
        .await
        .unwrap()
    else {
        panic!("first insert is new")
    };
    assert_eq!(a.state, JobState::Queued);
    assert_eq!(a.attempts, 0);
    assert_eq!(a.options, json!({ "restarts": 1 }));
    match store
        .insert_job(new_job(&id[1], "k1", Some("take-7")))
        .await
        .unwrap()
    {
        Inserted::Existing(j) => assert_eq!(j.id, id[0]),
        Inserted::New(_) => panic!("same owner and key must return the existing job"),
    }
    let Inserted::New(_) = store
        .insert_job(new_job(&id[1], "k2", Some("take-7")))
        .await
        .unwrap()
    else {
        panic!("another owner's key is another job")
    };
    let Inserted::New(_) = store.insert_job(new_job(&id[2], "k1", None)).await.unwrap() else {
        panic!("no key: new")
    };

    // Listing: newest first, per owner, cursor, state, idempotency key.
    let page = |f: JobFilter| async move {
        store
            .list_jobs(f)
            .await
            .unwrap()
            .into_iter()
            .map(|j| j.id)
            .collect::<Vec<_>>()
    };
    let mine = JobFilter {
        owner: Some("k1".into()),
        limit: 10,
        ..JobFilter::default()
    };
    assert_eq!(page(mine.clone()).await, [id[2].clone(), id[0].clone()]);
    assert_eq!(
        page(JobFilter {
            before: Some(id[2].clone()),
            ..mine.clone()
        })
        .await,
        [id[0].clone()]
    );
    assert_eq!(
        page(JobFilter {
            idempotency_key: Some("take-7".into()),
            ..mine.clone()
        })
        .await,
        [id[0].clone()]
    );
    assert!(page(JobFilter {
        state: Some(JobState::Running),
        ..mine.clone()
    })
    .await
    .is_empty());

    // Queue order and positions.
    assert_eq!(store.queue_position(&id[0]).await.unwrap(), Some(0));
    assert_eq!(store.queue_position(&id[2]).await.unwrap(), Some(2));
    let claimed = store.claim_next().await.unwrap().expect("a queued job");
    assert_eq!(claimed.id, id[0], "oldest first");
    assert_eq!(claimed.state, JobState::Running);
    assert_eq!(claimed.attempts, 1);
    assert!(claimed.started_at.is_some());
    assert_eq!(store.queue_position(&id[0]).await.unwrap(), None);
    assert_eq!(store.queue_position(&id[2]).await.unwrap(), Some(1));

    // Progress bumps the version (the ETag).
    store
        .set_progress(
            &id[0],
            ProgressRow {
                frames_done: 5,
                frames_total: Some(23),
                fps: 12.5,
            },
        )
        .await
        .unwrap();
    let j = store.job(&id[0]).await.unwrap().unwrap();
    assert_eq!(
        (j.frames_done, j.frames_total, j.fps),
        (5, Some(23), Some(12.5))
    );
    assert!(j.version > claimed.version);

    // Events: ordered, paged, a repeated number ignored.
    store
        .append_events(
            &id[0],
            vec![ev(1, "state"), ev(2, "progress"), ev(3, "progress")],
        )
        .await
        .unwrap();
    store
        .append_events(&id[0], vec![ev(3, "again")])
        .await
        .unwrap();
    let after = store.events_after(&id[0], 1, 10).await.unwrap();
    assert_eq!(after, vec![ev(2, "progress"), ev(3, "progress")]);
    assert_eq!(store.events_after(&id[0], 0, 1).await.unwrap().len(), 1);
    assert_eq!(store.last_event_seq(&id[0]).await.unwrap(), 3);
    // A new job's first event came with it.
    assert_eq!(store.last_event_seq(&id[2]).await.unwrap(), 1);
    assert_eq!(
        store.events_after(&id[2], 0, 10).await.unwrap(),
        vec![Event {
            seq: 1,
            kind: "state".into(),
            data: json!({ "state": "queued" }),
        }]
    );

    // Finishing only from the states named, with the final events.
    let done = Outcome {
        state: JobState::Succeeded,
        error: None,
        artifacts: vec![Artifact {
            name: "motion.bvh".into(),
            bytes: 99,
            content_type: "application/octet-stream".into(),
        }],
    };
    assert!(!store
        .finish(
            &id[0],
            &[JobState::Queued],
            done.clone(),
            vec![ev(4, "done")]
        )
        .await
        .unwrap());
    assert!(store
        .finish(
            &id[0],
            &[JobState::Running],
            done.clone(),
            vec![ev(4, "done")]
        )
        .await
        .unwrap());
    let j = store.job(&id[0]).await.unwrap().unwrap();
    assert_eq!(j.state, JobState::Succeeded);
    assert_eq!(j.artifacts, done.artifacts);
    assert!(j.finished_at.is_some());
    assert_eq!(store.last_event_seq(&id[0]).await.unwrap(), 4);
    assert!(!store
        .finish(
            &id[0],
            &[JobState::Queued, JobState::Running],
            done,
            vec![ev(5, "x")]
        )
        .await
        .unwrap());

    // Cancel a queued job (from either of two states).
    store.request_cancel(&id[2]).await.unwrap();
    let canceled = Outcome {
        state: JobState::Canceled,
        error: Some(JobError {
            code: "canceled".into(),
            message: "by the test".into(),
        }),
        artifacts: vec![],
    };
    assert!(store
        .finish(
            &id[2],
            &[JobState::Queued, JobState::Running],
            canceled,
            vec![]
        )
        .await
        .unwrap());
    let j = store.job(&id[2]).await.unwrap().unwrap();
    assert!(j.cancel_requested);
    assert_eq!(j.error.unwrap().code, "canceled");

    // Requeue (shutdown) does not count the attempt; recovery after a crash does,
    // and gives up after the last one.
    let b = store.claim_next().await.unwrap().unwrap();
    assert_eq!((b.id.as_str(), b.attempts), (id[1].as_str(), 1));
    store.requeue(&id[1]).await.unwrap();
    let j = store.job(&id[1]).await.unwrap().unwrap();
    assert_eq!((j.state, j.attempts), (JobState::Queued, 0));
    store.claim_next().await.unwrap().unwrap();
    let rec = store.recover(2).await.unwrap();
    assert_eq!(rec.len(), 1);
    assert_eq!((rec[0].state, rec[0].attempts), (JobState::Queued, 1));
    store.claim_next().await.unwrap().unwrap();
    let rec = store.recover(2).await.unwrap();
    assert_eq!((rec[0].state, rec[0].attempts), (JobState::Failed, 2));
    let j = store.job(&id[1]).await.unwrap().unwrap();
    assert_eq!(j.error.unwrap().code, "gave_up");
    assert!(store.claim_next().await.unwrap().is_none());

    let counts = store.count_by_state().await.unwrap();
    let n = |s| counts.iter().find(|(st, _)| *st == s).unwrap().1;
    assert_eq!(
        (
            n(JobState::Succeeded),
            n(JobState::Failed),
            n(JobState::Canceled)
        ),
        (1, 1, 1)
    );

    // Deleting takes the events; a clip shared by a rerun stays while used.
    let mut rerun = new_job(&id[3], "k1", None);
    rerun.clip_key = format!("clips/{}", id[0]);
    rerun.rerun_of = Some(id[0].clone());
    store.insert_job(rerun).await.unwrap();
    assert_eq!(
        store.clip_users(&format!("clips/{}", id[0])).await.unwrap(),
        2
    );
    let gone = store.delete_job(&id[0]).await.unwrap().unwrap();
    assert_eq!(gone.id, id[0]);
    assert!(store.job(&id[0]).await.unwrap().is_none());
    assert!(store.events_after(&id[0], 0, 10).await.unwrap().is_empty());
    assert_eq!(store.clip_users(&gone.clip_key).await.unwrap(), 1);
    assert!(store.delete_job(&id[0]).await.unwrap().is_none());

    // Keys: only the hash is looked up.
    assert_eq!(store.count_keys().await.unwrap(), 0);
    let k = store.create_key("key-1", "ci-bot", "abc123").await.unwrap();
    assert_eq!(k.name, "ci-bot");
    assert_eq!(store.count_keys().await.unwrap(), 1);
    assert_eq!(
        store.key_by_hash("abc123").await.unwrap().unwrap().id,
        "key-1"
    );
    assert!(store.key_by_hash("other").await.unwrap().is_none());
    store.ping().await.unwrap();
}

#[tokio::test]
async fn sqlite_store_keeps_its_contract() {
    let dir = common::TempDir::new("store");
    let store = SqlStore::open_sqlite(&dir.path("jobs.db")).await.unwrap();
    contract(&store).await;
    // The schema is applied once; reopening finds the data.
    drop(store);
    let again = SqlStore::open_sqlite(&dir.path("jobs.db")).await.unwrap();
    assert_eq!(again.count_keys().await.unwrap(), 1);
}

#[tokio::test]
async fn postgres_store_keeps_its_contract() {
    let Ok(base) = std::env::var("MONOCAP_TEST_DATABASE_URL") else {
        println!(
            "skipped: MONOCAP_TEST_DATABASE_URL is not set (a PostgreSQL server to test against)"
        );
        return;
    };
    let schema = format!(
        "monocap_test_{}_{}",
        std::process::id(),
        uuid::Uuid::now_v7().simple()
    );
    let admin = sqlx::PgPool::connect(&base)
        .await
        .expect("connect to PostgreSQL");
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE SCHEMA {schema}")))
        .execute(&admin)
        .await
        .unwrap();
    let sep = if base.contains('?') { '&' } else { '?' };
    let url = format!("{base}{sep}options=-c%20search_path%3D{schema}");
    let result = tokio::spawn(async move {
        let store = SqlStore::connect(&url).await.unwrap();
        contract(&store).await;
    })
    .await;
    sqlx::query(sqlx::AssertSqlSafe(format!("DROP SCHEMA {schema} CASCADE")))
        .execute(&admin)
        .await
        .unwrap();
    if let Err(e) = result {
        std::panic::resume_unwind(e.into_panic());
    }
}
