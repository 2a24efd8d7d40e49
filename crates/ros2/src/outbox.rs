//! The hand-off between the bus's receive thread and the thread that converts and sends to
//! ROS 2: bounded, dropping the oldest job when full and counting it against its route, so a
//! slow ROS subscriber (a reliable publisher blocking on its link) never holds up the bus.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use parking_lot::{Condvar, Mutex};

use super::mapping::Route;

/// Work for the sending thread: convert and put one message. Returns the bytes sent.
pub(crate) type Job = Box<dyn FnOnce() -> crate::error::Result<usize> + Send>;

/// What one route has done so far.
#[derive(Debug, Default)]
pub(crate) struct RouteCounters {
    pub sent: AtomicU64,
    pub bytes: AtomicU64,
    /// Dropped in the hand-off (the sender fell behind).
    pub dropped: AtomicU64,
    /// Conversion or put failed.
    pub failed: AtomicU64,
}

struct Queue {
    jobs: VecDeque<(Route, Job)>,
    closed: bool,
}

/// A bounded queue with one consumer thread.
pub(crate) struct Outbox {
    queue: Mutex<Queue>,
    ready: Condvar,
    capacity: usize,
    counters: Arc<dyn Fn(Route) -> Arc<RouteCounters> + Send + Sync>,
}

impl Outbox {
    /// An outbox of `capacity` jobs whose thread `name` runs them in order.
    pub(crate) fn start(
        name: &str,
        capacity: usize,
        counters: Arc<dyn Fn(Route) -> Arc<RouteCounters> + Send + Sync>,
    ) -> std::io::Result<(Arc<Outbox>, std::thread::JoinHandle<()>)> {
        let outbox = Arc::new(Outbox {
            queue: Mutex::new(Queue { jobs: VecDeque::with_capacity(capacity), closed: false }),
            ready: Condvar::new(),
            capacity: capacity.max(1),
            counters,
        });
        let worker = outbox.clone();
        let handle = std::thread::Builder::new().name(name.into()).spawn(move || worker.run())?;
        Ok((outbox, handle))
    }

    /// Queues `job`; when full, the oldest job is dropped and counted against its route.
    pub(crate) fn push(&self, route: Route, job: Job) {
        let dropped = {
            let mut q = self.queue.lock();
            if q.closed {
                return;
            }
            let dropped = (q.jobs.len() >= self.capacity).then(|| q.jobs.pop_front()).flatten();
            q.jobs.push_back((route, job));
            dropped
        };
        self.ready.notify_one();
        if let Some((r, _)) = dropped {
            (self.counters)(r).dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Ends the thread once the queued jobs are done.
    pub(crate) fn close(&self) {
        self.queue.lock().closed = true;
        self.ready.notify_all();
    }

    fn run(&self) {
        loop {
            let (route, job) = {
                let mut q = self.queue.lock();
                loop {
                    if let Some(next) = q.jobs.pop_front() {
                        break next;
                    }
                    if q.closed {
                        return;
                    }
                    self.ready.wait(&mut q);
                }
            };
            let c = (self.counters)(route);
            match job() {
                Ok(bytes) => {
                    c.sent.fetch_add(1, Ordering::Relaxed);
                    c.bytes.fetch_add(bytes as u64, Ordering::Relaxed);
                }
                Err(e) => {
                    if c.failed.fetch_add(1, Ordering::Relaxed) == 0 {
                        tracing::warn!(route = route.id(), "ROS 2 send failed (further failures counted only): {e:#}");
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn a_full_outbox_drops_the_oldest_and_counts_it() {
        let counters: Arc<BTreeMap<Route, Arc<RouteCounters>>> =
            Arc::new(Route::ALL.iter().map(|r| (*r, Arc::default())).collect());
        let c = counters.clone();
        let (outbox, handle) = Outbox::start("test-outbox", 2, Arc::new(move |r| c[&r].clone())).unwrap();
        let (gate_tx, gate_rx) = std::sync::mpsc::channel::<()>();
        let (started_tx, started_rx) = std::sync::mpsc::channel::<()>();
        // The first job holds the thread until the gate opens; three more arrive meanwhile.
        outbox.push(
            Route::Clock,
            Box::new(move || {
                let gone = |_| crate::error::Error::Panicked("the test");
                started_tx.send(()).map_err(|_| gone(()))?;
                gate_rx.recv().map(|_| 1).map_err(|_| gone(()))
            }),
        );
        started_rx.recv_timeout(std::time::Duration::from_secs(10)).unwrap();
        for _ in 0..3 {
            outbox.push(Route::Odometry, Box::new(|| Ok(10)));
        }
        gate_tx.send(()).unwrap();
        outbox.close();
        handle.join().unwrap();
        let odo = &counters[&Route::Odometry];
        assert_eq!(odo.dropped.load(Ordering::Relaxed), 1);
        assert_eq!(odo.sent.load(Ordering::Relaxed), 2);
        assert_eq!(odo.bytes.load(Ordering::Relaxed), 20);
        assert_eq!(counters[&Route::Clock].sent.load(Ordering::Relaxed), 1);
    }
}
