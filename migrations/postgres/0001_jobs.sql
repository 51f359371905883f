-- Jobs, their progress events and API keys (PostgreSQL).
CREATE TABLE api_keys (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    token_hash TEXT NOT NULL UNIQUE,
    created_at BIGINT NOT NULL
);

CREATE TABLE jobs (
    -- UUIDv7: ordered by creation, so "newest first" and queue order are id orders.
    id TEXT PRIMARY KEY,
    -- The API key that made the job ('' when the server runs without keys).
    owner TEXT NOT NULL,
    state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'canceled')),
    options TEXT NOT NULL,
    clip_key TEXT NOT NULL,
    clip_name TEXT NOT NULL,
    clip_bytes BIGINT NOT NULL,
    clip_info TEXT NOT NULL,
    idempotency_key TEXT,
    rerun_of TEXT,
    attempts BIGINT NOT NULL DEFAULT 0,
    cancel_requested BIGINT NOT NULL DEFAULT 0,
    frames_done BIGINT NOT NULL DEFAULT 0,
    frames_total BIGINT,
    fps DOUBLE PRECISION,
    error_code TEXT,
    error_message TEXT,
    artifacts TEXT NOT NULL DEFAULT '[]',
    created_at BIGINT NOT NULL,
    started_at BIGINT,
    finished_at BIGINT,
    updated_at BIGINT NOT NULL,
    -- Bumped on every change: the job's ETag.
    version BIGINT NOT NULL DEFAULT 0
);
CREATE UNIQUE INDEX jobs_idempotency ON jobs (owner, idempotency_key) WHERE idempotency_key IS NOT NULL;
CREATE INDEX jobs_state ON jobs (state, id);
CREATE INDEX jobs_owner ON jobs (owner, id);

CREATE TABLE job_events (
    job_id TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    seq BIGINT NOT NULL,
    kind TEXT NOT NULL,
    data TEXT NOT NULL,
    PRIMARY KEY (job_id, seq)
);
