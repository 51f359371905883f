//! The progress bus: per job that is queued or running in this process, the events
//! it emitted since this process took it up, and a signal to wake its subscribers.
//!
//! Every event has a per-job sequence number that continues the ones already in the
//! database, and is kept here until the job ends, so a subscriber that reads the
//! database first and then this log sees every event once, in order, however late it
//! comes. The database gets the events too (state changes at once, per-frame
//! progress in batches); once a job has ended its log here is dropped and the
//! database alone answers.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use tokio::sync::watch;

use crate::store::Event;

/// One job's live log.
pub struct Live {
    inner: Mutex<Inner>,
    signal: watch::Sender<i64>,
}

struct Inner {
    events: Vec<Event>,
    next_seq: i64,
    /// Events before this index are in the database.
    flushed: usize,
    closed: bool,
}

impl Live {
    fn new(next_seq: i64) -> Live {
        Live {
            inner: Mutex::new(Inner {
                events: Vec::new(),
                next_seq,
                flushed: 0,
                closed: false,
            }),
            signal: watch::channel(next_seq - 1).0,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock leaves consistent data (pushes are atomic).
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Appends an event and wakes the subscribers; returns it with its number.
    pub fn emit(&self, kind: &str, data: serde_json::Value) -> Event {
        let event = {
            let mut g = self.lock();
            let e = Event {
                seq: g.next_seq,
                kind: kind.to_string(),
                data,
            };
            g.next_seq += 1;
            g.events.push(e.clone());
            e
        };
        self.signal.send_replace(event.seq);
        event
    }

    /// Numbers events without publishing them (to store them first; see
    /// [`Live::publish`]). Only one task may prepare events of a job at a time.
    pub fn prepare(&self, events: Vec<(&str, serde_json::Value)>) -> Vec<Event> {
        let next = self.lock().next_seq;
        events
            .into_iter()
            .enumerate()
            .map(|(i, (kind, data))| Event {
                seq: next + i as i64,
                kind: kind.to_string(),
                data,
            })
            .collect()
    }

    /// Publishes events made by [`Live::prepare`] and already stored, in order.
    pub fn publish(&self, events: &[Event]) {
        let Some(last) = events.last() else { return };
        {
            let mut g = self.lock();
            let all_flushed = g.flushed == g.events.len();
            g.events.extend(events.iter().cloned());
            g.next_seq = last.seq + 1;
            if all_flushed {
                g.flushed = g.events.len();
            }
        }
        self.signal.send_replace(last.seq);
    }

    /// Events after `seq`, and whether the log is closed (no more will come).
    pub fn after(&self, seq: i64) -> (Vec<Event>, bool) {
        let g = self.lock();
        let start = g.events.partition_point(|e| e.seq <= seq);
        (g.events[start..].to_vec(), g.closed)
    }

    /// The events not yet written to the database (marked written).
    pub fn take_unflushed(&self) -> Vec<Event> {
        let mut g = self.lock();
        let out = g.events[g.flushed..].to_vec();
        g.flushed = g.events.len();
        out
    }

    /// Marks the events up to and including `seq` as written to the database.
    pub fn mark_flushed(&self, seq: i64) {
        let mut g = self.lock();
        g.flushed = g.events.partition_point(|e| e.seq <= seq);
    }

    /// A receiver woken on every new event and on close.
    pub fn subscribe(&self) -> watch::Receiver<i64> {
        self.signal.subscribe()
    }

    /// No more events will come.
    pub fn close(&self) {
        self.lock().closed = true;
        self.signal.send_modify(|_| {});
    }
}

/// The live logs by job id.
#[derive(Default)]
pub struct Bus {
    jobs: Mutex<HashMap<String, Arc<Live>>>,
}

impl Bus {
    pub fn new() -> Bus {
        Bus::default()
    }

    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<Live>>> {
        self.jobs.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn get(&self, id: &str) -> Option<Arc<Live>> {
        self.map().get(id).cloned()
    }

    /// The job's log, opened with events numbered from `next_seq` if it has none.
    pub fn open(&self, id: &str, next_seq: i64) -> Arc<Live> {
        self.map()
            .entry(id.to_string())
            .or_insert_with(|| Arc::new(Live::new(next_seq)))
            .clone()
    }

    /// Closes and forgets the job's log.
    pub fn remove(&self, id: &str) {
        if let Some(live) = self.map().remove(id) {
            live.close();
        }
    }

    /// How many jobs have a live log.
    pub fn len(&self) -> usize {
        self.map().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_are_numbered_on_from_the_database_and_read_after_a_cursor() {
        let bus = Bus::new();
        let live = bus.open("a", 5);
        let mut rx = live.subscribe();
        assert_eq!(live.emit("state", serde_json::json!({})).seq, 5);
        assert_eq!(live.emit("progress", serde_json::json!({})).seq, 6);
        assert!(rx.has_changed().unwrap());
        assert_eq!(*rx.borrow_and_update(), 6);
        let (after, closed) = live.after(5);
        assert_eq!(after.iter().map(|e| e.seq).collect::<Vec<_>>(), [6]);
        assert!(!closed);
        assert_eq!(live.take_unflushed().len(), 2);
        assert!(live.take_unflushed().is_empty());
        // A second open finds the same log.
        assert_eq!(bus.open("a", 1).emit("x", serde_json::json!(1)).seq, 7);
        bus.remove("a");
        assert!(live.after(7).1, "removed logs are closed");
        assert!(bus.get("a").is_none());
    }
}
