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
    /// Ordered by number, each with whether the database has it.
    events: Vec<(Event, bool)>,
    /// The next number to give (numbers given are never given again).
    next_seq: i64,
    closed: bool,
}

impl Live {
    fn new(next_seq: i64) -> Live {
        Live {
            inner: Mutex::new(Inner {
                events: Vec::new(),
                next_seq,
                closed: false,
            }),
            signal: watch::channel(next_seq - 1).0,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock leaves consistent data (pushes are atomic).
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Appends an event (to be stored later) and wakes the subscribers; returns it
    /// with its number.
    pub fn emit(&self, kind: &str, data: serde_json::Value) -> Event {
        let event = {
            let mut g = self.lock();
            let e = Event {
                seq: g.next_seq,
                kind: kind.to_string(),
                data,
            };
            g.next_seq += 1;
            g.events.push((e.clone(), false));
            e
        };
        self.signal.send_replace(event.seq);
        event
    }

    /// Numbers events without publishing them, to store them first (see
    /// [`Live::publish`]); the numbers are reserved, so events emitted meanwhile get
    /// later ones. Numbers of events never published are simply skipped.
    pub fn prepare(&self, events: Vec<(&str, serde_json::Value)>) -> Vec<Event> {
        let mut g = self.lock();
        let next = g.next_seq;
        g.next_seq += events.len() as i64;
        numbered(next, events)
    }

    /// Publishes events made by [`Live::prepare`] and already stored.
    pub fn publish(&self, events: &[Event]) {
        let Some(last) = events.iter().map(|e| e.seq).max() else {
            return;
        };
        {
            let mut g = self.lock();
            for e in events {
                let at = g.events.partition_point(|(x, _)| x.seq < e.seq);
                g.events.insert(at, (e.clone(), true));
            }
            g.next_seq = g.next_seq.max(last + 1);
        }
        self.signal.send_replace(last);
    }

    /// Events after `seq`, and whether the log is closed (no more will come).
    pub fn after(&self, seq: i64) -> (Vec<Event>, bool) {
        let g = self.lock();
        let start = g.events.partition_point(|(e, _)| e.seq <= seq);
        (
            g.events[start..].iter().map(|(e, _)| e.clone()).collect(),
            g.closed,
        )
    }

    /// The events the database does not have yet (see [`Live::mark_stored`]).
    pub fn unstored(&self) -> Vec<Event> {
        let g = self.lock();
        g.events
            .iter()
            .filter(|(_, stored)| !stored)
            .map(|(e, _)| e.clone())
            .collect()
    }

    /// Marks the events up to and including `seq` as stored.
    pub fn mark_stored(&self, seq: i64) {
        let mut g = self.lock();
        for (e, stored) in g.events.iter_mut() {
            if e.seq <= seq {
                *stored = true;
            }
        }
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

/// Events numbered from `next` on.
pub fn numbered(next: i64, events: Vec<(&str, serde_json::Value)>) -> Vec<Event> {
    events
        .into_iter()
        .zip(next..)
        .map(|((kind, data), seq)| Event {
            seq,
            kind: kind.to_string(),
            data,
        })
        .collect()
}

/// The live logs by job id, and a signal raised whenever a job's log opens or a
/// job ends.
pub struct Bus {
    jobs: Mutex<HashMap<String, Arc<Live>>>,
    changes: watch::Sender<u64>,
}

impl Default for Bus {
    fn default() -> Bus {
        Bus {
            jobs: Mutex::default(),
            changes: watch::channel(0).0,
        }
    }
}

impl Bus {
    pub fn new() -> Bus {
        Bus::default()
    }

    /// A receiver woken when a job's log opens or a job ends (see [`Bus::changed`]).
    ///
    /// A subscriber to a job with no log in this process polls the database; a job
    /// can start, end and be deleted (its stored events with it) between two polls.
    /// Woken at once instead, it takes the log while the job runs, or reads the
    /// final events before the deletion, which waits for the job to end.
    pub fn changes(&self) -> watch::Receiver<u64> {
        self.changes.subscribe()
    }

    /// Wakes the receivers of [`Bus::changes`] (a job ended, or its log opened).
    pub fn changed(&self) {
        self.changes.send_modify(|n| *n = n.wrapping_add(1));
    }

    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<Live>>> {
        self.jobs.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn get(&self, id: &str) -> Option<Arc<Live>> {
        self.map().get(id).cloned()
    }

    /// The job's log, opened with events numbered from `next_seq` if it has none.
    pub fn open(&self, id: &str, next_seq: i64) -> Arc<Live> {
        use std::collections::hash_map::Entry;
        let opened = match self.map().entry(id.to_string()) {
            Entry::Occupied(e) => return e.get().clone(),
            Entry::Vacant(e) => e.insert(Arc::new(Live::new(next_seq))).clone(),
        };
        self.changed();
        opened
    }

    /// Closes and forgets the job's log.
    pub fn remove(&self, id: &str) {
        if let Some(live) = self.map().remove(id) {
            live.close();
        }
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
        assert_eq!(live.unstored().len(), 2);
        live.mark_stored(6);
        assert!(live.unstored().is_empty());
        // Prepared numbers are reserved: an event emitted meanwhile comes after them,
        // and publishing puts them in order.
        let prepared = live.prepare(vec![("state", serde_json::json!({}))]);
        assert_eq!(prepared[0].seq, 7);
        assert_eq!(live.emit("progress", serde_json::json!({})).seq, 8);
        live.publish(&prepared);
        let (after, _) = live.after(6);
        assert_eq!(after.iter().map(|e| e.seq).collect::<Vec<_>>(), [7, 8]);
        assert_eq!(
            live.unstored().iter().map(|e| e.seq).collect::<Vec<_>>(),
            [8]
        );
        // A second open finds the same log.
        assert_eq!(bus.open("a", 1).emit("x", serde_json::json!(1)).seq, 9);
        bus.remove("a");
        assert!(live.after(9).1, "removed logs are closed");
        assert!(bus.get("a").is_none());
    }

    #[test]
    fn watchers_wake_when_a_log_opens_or_a_job_ends() {
        let bus = Bus::new();
        let mut rx = bus.changes();
        assert!(!rx.has_changed().unwrap());
        bus.open("a", 1);
        assert!(rx.has_changed().unwrap(), "a log opened");
        rx.borrow_and_update();
        bus.open("a", 1);
        assert!(!rx.has_changed().unwrap(), "the same log again");
        bus.changed();
        assert!(rx.has_changed().unwrap(), "a job ended");
    }
}
