//! The tracker's second core: each frame's features (distance transforms, edge map,
//! outline candidates: all that depends on the frame alone) are computed on helper
//! threads a few frames ahead of the search, and the independent fits of the
//! initialisation run side by side. Results are the same as on one thread: every
//! piece of work is the one a single thread would do, and its result is used in the
//! same order.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::Scope;

use super::tracker::{FrameInput, TrackError};
use crate::vision::features::{compute_unlinked, FeatureOptions, FrameFeatures};

/// Most threads a tracker uses, whatever it is told.
pub const MAX_THREADS: usize = 64;

/// How many threads a tracker uses when not told: the machine's cores.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// One frame in the order the input gave it.
enum Slot {
    /// Sent to the helper `worker`; its features come back on that helper's channel.
    Computing {
        index: usize,
        worker: usize,
    },
    /// Computed here (no helpers).
    Ready(usize, Box<FrameFeatures>),
    Failed(TrackError),
}

/// The input frames' unlinked features ([`compute_unlinked`]), in frame order,
/// computed up to `ahead` frames before they are asked for.
pub(crate) struct Prefetch<I> {
    inputs: std::iter::Enumerate<I>,
    exhausted: bool,
    size: (u32, u32),
    workers: Vec<(SyncSender<FrameInput>, Receiver<FrameFeatures>)>,
    /// The next helper to send a frame to (round robin, so each helper's results
    /// come back in frame order).
    next_worker: usize,
    queue: VecDeque<Slot>,
    ahead: usize,
    opts: FeatureOptions,
}

impl<I: Iterator<Item = anyhow::Result<FrameInput>>> Prefetch<I> {
    /// `helpers` threads in `scope` (none: each frame is computed when asked for).
    /// Frames of another size than `size` come out as [`TrackError::FrameSize`].
    pub fn new<'scope>(
        scope: &'scope Scope<'scope, '_>,
        inputs: I,
        size: (u32, u32),
        helpers: usize,
        opts: &FeatureOptions,
    ) -> Prefetch<I> {
        // At most `ahead` (≤ capacity) frames are in flight: no send ever waits.
        let capacity = 2 * helpers;
        // A helper the system cannot start is done without (its frames go to the
        // others, or are computed here).
        let workers: Vec<_> = (0..helpers)
            .map_while(|_| {
                let (job_tx, job_rx) = sync_channel::<FrameInput>(capacity);
                let (out_tx, out_rx) = sync_channel::<FrameFeatures>(capacity);
                let opts = opts.clone();
                std::thread::Builder::new()
                    .name("monocap-features".into())
                    .spawn_scoped(scope, move || {
                        for input in job_rx {
                            let f =
                                compute_unlinked(&input.silhouette, input.image.as_ref(), &opts);
                            if out_tx.send(f).is_err() {
                                break;
                            }
                        }
                    })
                    .ok()
                    .map(|_| (job_tx, out_rx))
            })
            .collect();
        let ahead = 2 * workers.len();
        Prefetch {
            inputs: inputs.enumerate(),
            exhausted: false,
            size,
            workers,
            next_worker: 0,
            queue: VecDeque::new(),
            ahead,
            opts: opts.clone(),
        }
    }

    /// Reads input frames until `ahead` are on their way (or the input ends). A
    /// frame that fails ends the reading: the input is not asked for more, as
    /// tracking ends there.
    fn fill(&mut self) {
        while !self.exhausted && self.queue.len() < self.ahead.max(1) {
            let Some((index, input)) = self.inputs.next() else {
                self.exhausted = true;
                break;
            };
            let slot = match input {
                Err(e) => Slot::Failed(TrackError::Input(e)),
                Ok(input) => self.start(index, input),
            };
            self.exhausted = matches!(slot, Slot::Failed(_));
            self.queue.push_back(slot);
        }
    }

    fn start(&mut self, index: usize, input: FrameInput) -> Slot {
        let (w, h) = self.size;
        if input.silhouette.width() != w || input.silhouette.height() != h {
            return Slot::Failed(TrackError::FrameSize {
                index,
                width: input.silhouette.width(),
                height: input.silhouette.height(),
                expected_w: w,
                expected_h: h,
            });
        }
        if self.workers.is_empty() {
            let f = compute_unlinked(&input.silhouette, input.image.as_ref(), &self.opts);
            return Slot::Ready(index, Box::new(f));
        }
        let worker = self.next_worker;
        self.next_worker = (worker + 1) % self.workers.len();
        self.workers[worker]
            .0
            .send(input)
            .expect("a feature helper ended early");
        Slot::Computing { index, worker }
    }

    /// The next frame's index and unlinked features; None after the last frame.
    pub fn next(&mut self) -> Option<Result<(usize, FrameFeatures), TrackError>> {
        self.fill();
        let slot = self.queue.pop_front()?;
        let out = match slot {
            Slot::Failed(e) => Err(e),
            Slot::Ready(index, f) => Ok((index, *f)),
            Slot::Computing { index, worker } => {
                let f = self.workers[worker]
                    .1
                    .recv()
                    .expect("a feature helper ended early");
                Ok((index, f))
            }
        };
        // Keep the helpers busy while the caller searches this frame.
        self.fill();
        Some(out)
    }
}

/// `f` over `items` on up to `threads` threads, which end before this returns;
/// results in the order of `items`. Each thread takes the next item not yet taken,
/// so one slow item does not leave the other threads idle behind a fixed share.
/// Items whose thread the system cannot start are mapped on the caller's thread.
pub(crate) fn par_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.clamp(1, items.len().max(1));
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let take = || -> Vec<(usize, R)> {
        let mut done = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(item) = items.get(i) else {
                return done;
            };
            done.push((i, f(item)));
        }
    };
    let take = &take;
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (1..threads)
            .map(|_| std::thread::Builder::new().spawn_scoped(s, take))
            .collect();
        // The caller's thread takes items too, and all that no thread started for.
        let mut parts = vec![take()];
        for h in handles.into_iter().flatten() {
            parts.push(h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
        }
        parts
    });
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    for part in parts.iter_mut() {
        for (i, r) in part.drain(..) {
            out[i] = Some(r);
        }
    }
    out.into_iter()
        .map(|r| r.expect("every item mapped"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn par_map_keeps_the_order_of_its_items() {
        let items: Vec<u64> = (0..13).collect();
        for threads in [1, 2, 3, 20] {
            let out = par_map(&items, threads, |&x| x * x + 1);
            assert_eq!(out, items.iter().map(|x| x * x + 1).collect::<Vec<_>>());
        }
        assert!(par_map(&[] as &[u8], 4, |&x| x).is_empty());
    }
}
