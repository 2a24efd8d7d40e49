//! Fault injection where samples enter a node: delay, jitter, loss (independent or bursty),
//! duplication, reordering, a bandwidth cap and outages, as a fault profile
//! ([`crate::config::FaultProfile`]) says per topic.
//!
//! Everything is counted on simulated time and drawn from counter-based random numbers
//! (a hash of the profile's seed, the topic, the node and the message's sequence number), so
//! a message's fate does not depend on when it arrived or on what else arrived: a lockstep run
//! with faults is repeatable, and the same seed drops the same messages.
//!
//! A node's simulated "now" is its [`NodeClock`]: the newest header stamp any of its
//! subscriptions received, or what the node sets itself (the simulator sets its step's time).
//! A delayed message is held in its subscription's [`Gate`] until the clock reaches its
//! release time, then handed on exactly as if it had just arrived. Arrivals (before faults)
//! are still recorded in the subscription's statistics, so real losses (sequence gaps) and
//! injected ones are counted apart.

use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Weak};

use parking_lot::Mutex;

use super::TopicStats;
use crate::config::{JitterDist, Loss, TopicFaults};
use crate::msg::Header;

/// A node's simulated now, for releasing delayed messages.
#[derive(Default)]
pub struct NodeClock {
    now_ns: AtomicU64,
    gates: Mutex<Vec<Weak<dyn Release>>>,
}

/// Something holding messages until a simulated time.
pub(crate) trait Release: Send + Sync {
    fn release(&self, now_ns: u64);
}

impl NodeClock {
    /// The newest simulated time this node has seen.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::Acquire)
    }

    /// Moves the clock on to `t_ns` (never back) and hands on every held message now due.
    pub fn advance(&self, t_ns: u64) {
        let before = self.now_ns.fetch_max(t_ns, Ordering::AcqRel);
        if t_ns <= before {
            return;
        }
        let gates: Vec<Arc<dyn Release>> = {
            let mut g = self.gates.lock();
            g.retain(|w| w.strong_count() > 0);
            g.iter().filter_map(Weak::upgrade).collect()
        };
        for gate in gates {
            gate.release(t_ns);
        }
    }

    pub(crate) fn register(&self, gate: Weak<dyn Release>) {
        self.gates.lock().push(gate);
    }
}

/// Why a message was not delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    Loss,
    Outage,
    /// It would have waited longer than `queue_ms` behind the bandwidth cap.
    Queue,
}

/// What happens to one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    Drop(Dropped),
    /// Handed on at simulated time `at_ns`, `copies` times (2: duplicated).
    Deliver {
        at_ns: u64,
        copies: u8,
    },
}

/// The fault model of one topic at one node: deterministic in (seed, topic, node, seq).
#[derive(Debug, Clone)]
pub struct Model {
    faults: TopicFaults,
    key: u64,
    /// Gilbert-Elliott state and the next sequence number it has not stepped over.
    bad: bool,
    next_seq: Option<u64>,
    /// When the capped link is free again, simulated ns.
    link_free_ns: u64,
    /// The latest release time handed out (order is kept unless `reorder`).
    last_release_ns: u64,
}

/// Streams of random numbers, one per use, so changing one fault does not move the others.
const LOSS: u64 = 1;
const CHAIN: u64 = 2;
const JITTER: u64 = 3;
const JITTER2: u64 = 4;
const DUPLICATE: u64 = 5;
/// A chain this far behind is drawn from its stationary distribution instead of stepped.
const MAX_CHAIN_STEPS: u64 = 10_000;

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

fn fnv(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

impl Model {
    pub fn new(faults: TopicFaults, seed: u64, topic: &str, node: &str) -> Model {
        let key = splitmix(seed ^ splitmix(fnv(topic) ^ splitmix(fnv(node))));
        Model { faults, key, bad: false, next_seq: None, link_free_ns: 0, last_release_ns: 0 }
    }

    /// A uniform number in [0, 1) for message `seq`, stream `stream`.
    fn uniform(&self, seq: u64, stream: u64) -> f64 {
        let x = splitmix(self.key ^ splitmix(seq.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ stream));
        (x >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Steps the Gilbert-Elliott chain to message `seq`; whether it is in the bad state there.
    fn chain_at(&mut self, seq: u64, p: f64, r: f64) -> bool {
        let from = match self.next_seq {
            Some(n) if seq >= n && seq - n < MAX_CHAIN_STEPS => n,
            // First message, a restarted publisher or a long gap: start from the stationary
            // distribution.
            _ => {
                self.bad = p + r > 0.0 && self.uniform(seq, CHAIN) < p / (p + r);
                self.next_seq = Some(seq + 1);
                return self.bad;
            }
        };
        for s in from..=seq {
            let u = self.uniform(s, CHAIN);
            self.bad = if self.bad { u >= r } else { u < p };
        }
        self.next_seq = Some(seq + 1);
        self.bad
    }

    fn jitter_ns(&self, seq: u64) -> u64 {
        let Some(j) = self.faults.jitter else { return 0 };
        let u = self.uniform(seq, JITTER);
        let ms = match j.dist {
            JitterDist::Uniform => u * j.ms,
            JitterDist::Exponential => -(1.0 - u).ln() * j.ms,
            JitterDist::Normal => {
                let u2 = self.uniform(seq, JITTER2);
                ((-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()).abs() * j.ms
            }
        };
        (ms * 1e6) as u64
    }

    /// The fate of the message with `header`, `len` bytes long.
    pub fn fate(&mut self, header: &Header, len: usize) -> Fate {
        let (seq, stamp) = (header.seq, header.stamp_sim_ns);
        let t_s = stamp as f64 / 1e9;
        // The chain steps with every message, whatever else happens to it.
        let lost = match self.faults.loss {
            Some(Loss::Independent(p)) => self.uniform(seq, LOSS) < p,
            Some(Loss::Bursty(ge)) => {
                let bad = self.chain_at(seq, ge.good_to_bad, ge.bad_to_good);
                self.uniform(seq, LOSS) < if bad { ge.loss_in_bad } else { ge.loss_in_good }
            }
            None => false,
        };
        if self.faults.outages.iter().any(|o| o.from_s <= t_s && t_s < o.to_s) {
            return Fate::Drop(Dropped::Outage);
        }
        if lost {
            return Fate::Drop(Dropped::Loss);
        }
        let mut at = stamp;
        if let Some(mbps) = self.faults.bandwidth_mbps {
            let send_ns = (len as f64 * 8.0 / (mbps * 1e6) * 1e9) as u64;
            let done = self.link_free_ns.max(stamp) + send_ns;
            if done - stamp > (self.faults.queue_ms * 1e6) as u64 {
                return Fate::Drop(Dropped::Queue);
            }
            self.link_free_ns = done;
            at = done;
        }
        at += (self.faults.delay_ms * 1e6) as u64 + self.jitter_ns(seq);
        if !self.faults.reorder {
            at = at.max(self.last_release_ns);
        }
        self.last_release_ns = self.last_release_ns.max(at);
        let copies = if self.uniform(seq, DUPLICATE) < self.faults.duplicate { 2 } else { 1 };
        Fate::Deliver { at_ns: at, copies }
    }
}

/// A message held until its release time; ordered by (time, arrival) for the heap.
struct Held<T> {
    at_ns: u64,
    order: u64,
    item: T,
}

impl<T> PartialEq for Held<T> {
    fn eq(&self, o: &Self) -> bool {
        (self.at_ns, self.order) == (o.at_ns, o.order)
    }
}
impl<T> Eq for Held<T> {}
impl<T> PartialOrd for Held<T> {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl<T> Ord for Held<T> {
    // Reversed: BinaryHeap is a max-heap, the earliest release comes out first.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (o.at_ns, o.order).cmp(&(self.at_ns, self.order))
    }
}

struct GateState<T> {
    model: Model,
    held: BinaryHeap<Held<T>>,
    order: u64,
}

/// Applies one topic's faults to one subscription: drops, holds and duplicates what arrives,
/// hands the rest on through `deliver`.
pub(crate) struct Gate<T> {
    state: Mutex<GateState<T>>,
    clock: Arc<NodeClock>,
    stats: Arc<TopicStats>,
    deliver: Box<dyn Fn(T) + Send + Sync>,
}

impl<T: Clone + Send + 'static> Gate<T> {
    pub(crate) fn new(
        model: Model,
        clock: Arc<NodeClock>,
        stats: Arc<TopicStats>,
        deliver: impl Fn(T) + Send + Sync + 'static,
    ) -> Arc<Gate<T>> {
        let gate = Arc::new(Gate {
            state: Mutex::new(GateState { model, held: BinaryHeap::new(), order: 0 }),
            clock: clock.clone(),
            stats,
            deliver: Box::new(deliver),
        });
        let weak: Weak<dyn Release> = Arc::downgrade(&(gate.clone() as Arc<dyn Release>));
        clock.register(weak);
        gate
    }

    /// A message arrived (already decoded and counted as received).
    pub(crate) fn arrive(&self, header: &Header, len: usize, item: T) {
        // Its own stamp moves the node's clock first: what was due by now goes out before it.
        self.clock.advance(header.stamp_sim_ns);
        let mut st = self.state.lock();
        let fate = st.model.fate(header, len);
        let (at_ns, copies) = match fate {
            Fate::Drop(_) => {
                self.stats.on_injected_drop();
                return;
            }
            Fate::Deliver { at_ns, copies } => (at_ns, copies),
        };
        if at_ns > header.stamp_sim_ns {
            self.stats.on_injected_delay();
        }
        if copies > 1 {
            self.stats.on_injected_duplicate();
            let order = st.order;
            st.order += 1;
            st.held.push(Held { at_ns, order, item: item.clone() });
        }
        let order = st.order;
        st.order += 1;
        st.held.push(Held { at_ns, order, item });
        // The lock is held while handing on, so two threads never deliver out of order.
        self.flush(&mut st, self.clock.now_ns());
    }

    fn flush(&self, st: &mut GateState<T>, now_ns: u64) {
        while st.held.peek().is_some_and(|h| h.at_ns <= now_ns) {
            if let Some(h) = st.held.pop() {
                (self.deliver)(h.item);
            }
        }
    }
}

impl<T: Clone + Send + 'static> Release for Gate<T> {
    fn release(&self, now_ns: u64) {
        let mut st = self.state.lock();
        self.flush(&mut st, now_ns);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{GilbertElliott, Jitter, Outage};

    fn faults() -> TopicFaults {
        TopicFaults::default()
    }

    fn h(seq: u64) -> Header {
        Header { seq, stamp_sim_ns: seq * 10_000_000, stamp_pub_ns: 0 }
    }

    fn fates(f: TopicFaults, seed: u64, n: u64) -> Vec<Fate> {
        let mut m = Model::new(f, seed, "perception/objects", "acc");
        (0..n).map(|s| m.fate(&h(s), 100)).collect()
    }

    fn lost(v: &[Fate]) -> Vec<bool> {
        v.iter().map(|f| matches!(f, Fate::Drop(_))).collect()
    }

    #[test]
    fn the_same_seed_gives_the_same_fates_and_another_seed_others() {
        let f = TopicFaults { loss: Some(Loss::Independent(0.3)), ..faults() };
        assert_eq!(fates(f.clone(), 7, 1000), fates(f.clone(), 7, 1000));
        assert_ne!(lost(&fates(f.clone(), 7, 1000)), lost(&fates(f, 8, 1000)));
    }

    #[test]
    fn a_fate_does_not_depend_on_what_came_before() {
        // Message 500's fate is the same whether or not messages 0..500 were seen (real
        // losses before it do not move the injected ones).
        let f = TopicFaults { loss: Some(Loss::Independent(0.5)), ..faults() };
        let all = fates(f.clone(), 1, 1000);
        let mut m = Model::new(f, 1, "perception/objects", "acc");
        let later: Vec<Fate> = (500..1000).map(|s| m.fate(&h(s), 100)).collect();
        assert_eq!(lost(&all[500..]), lost(&later));
    }

    #[test]
    fn independent_loss_loses_its_share_and_bursty_loss_comes_in_bursts() {
        let n = 100_000;
        let indep = lost(&fates(TopicFaults { loss: Some(Loss::Independent(0.2)), ..faults() }, 3, n));
        let bursty = lost(&fates(
            TopicFaults { loss: Some(Loss::Bursty(GilbertElliott::with_mean(0.2, 5.0))), ..faults() },
            3,
            n,
        ));
        let share = |v: &[bool]| v.iter().filter(|l| **l).count() as f64 / v.len() as f64;
        let mean_burst = |v: &[bool]| {
            let bursts = v.windows(2).filter(|w| !w[0] && w[1]).count().max(1);
            v.iter().filter(|l| **l).count() as f64 / bursts as f64
        };
        assert!((share(&indep) - 0.2).abs() < 0.01, "{}", share(&indep));
        assert!((share(&bursty) - 0.2).abs() < 0.02, "{}", share(&bursty));
        assert!((mean_burst(&indep) - 1.25).abs() < 0.1, "independent bursts {}", mean_burst(&indep));
        assert!((mean_burst(&bursty) - 5.0).abs() < 0.5, "bursty bursts {}", mean_burst(&bursty));
    }

    #[test]
    fn outages_drop_everything_inside_them_and_nothing_outside() {
        let f = TopicFaults { outages: vec![Outage { from_s: 1.0, to_s: 2.0 }], ..faults() };
        let v = fates(f, 1, 300);
        for (seq, fate) in v.iter().enumerate() {
            let inside = (100..200).contains(&seq);
            assert_eq!(*fate == Fate::Drop(Dropped::Outage), inside, "seq {seq}: {fate:?}");
        }
    }

    #[test]
    fn delay_and_jitter_release_later_in_order_unless_reordering_is_allowed() {
        let f =
            TopicFaults { delay_ms: 50.0, jitter: Some(Jitter { dist: JitterDist::Uniform, ms: 40.0 }), ..faults() };
        let at = |v: &[Fate]| -> Vec<u64> {
            v.iter().map(|f| if let Fate::Deliver { at_ns, .. } = f { *at_ns } else { 0 }).collect()
        };
        let ordered = at(&fates(f.clone(), 1, 500));
        for (seq, t) in ordered.iter().enumerate() {
            let stamp = seq as u64 * 10_000_000;
            assert!(*t >= stamp + 50_000_000, "seq {seq}: released before its delay");
        }
        assert!(ordered.windows(2).all(|w| w[1] >= w[0]), "order kept");
        let reordered = at(&fates(TopicFaults { reorder: true, ..f }, 1, 500));
        assert!(reordered.windows(2).any(|w| w[1] < w[0]), "jitter of 40 ms on 10 ms spacing reorders");
        for (seq, t) in reordered.iter().enumerate() {
            let extra = t - (seq as u64 * 10_000_000 + 50_000_000);
            assert!(extra <= 40_000_000, "uniform jitter stays within its width: {extra}");
        }
    }

    #[test]
    fn a_bandwidth_cap_queues_and_drops_what_would_wait_too_long() {
        // 1 Mbit/s, 2,500-byte messages every 10 ms: 20 ms each on the link, twice the rate
        // it can carry; the queue grows 10 ms per message until it passes 100 ms.
        let f = TopicFaults { bandwidth_mbps: Some(1.0), queue_ms: 100.0, ..faults() };
        let mut m = Model::new(f, 1, "camera/front", "detect");
        let v: Vec<Fate> = (0..40).map(|s| m.fate(&h(s), 2_500)).collect();
        assert_eq!(v[0], Fate::Deliver { at_ns: 20_000_000, copies: 1 });
        assert_eq!(v[1], Fate::Deliver { at_ns: 40_000_000, copies: 1 });
        assert!(v.contains(&Fate::Drop(Dropped::Queue)), "{v:?}");
        for (seq, f) in v.iter().enumerate() {
            if let Fate::Deliver { at_ns, .. } = f {
                assert!(at_ns - seq as u64 * 10_000_000 <= 100_000_000, "queued beyond queue_ms");
            }
        }
    }

    #[test]
    fn a_gate_holds_delayed_messages_until_the_node_clock_reaches_them() {
        let clock = Arc::new(NodeClock::default());
        let stats = Arc::new(TopicStats::new("perception/objects"));
        let out = Arc::new(Mutex::new(Vec::new()));
        let sink = out.clone();
        let f = TopicFaults { delay_ms: 25.0, duplicate: 1.0, ..faults() };
        let gate = Gate::new(Model::new(f, 1, "perception/objects", "acc"), clock.clone(), stats.clone(), move |s| {
            sink.lock().push(s)
        });
        gate.arrive(&h(0), 10, 0u64);
        assert!(out.lock().is_empty(), "held: 25 ms not yet passed");
        clock.advance(20_000_000);
        assert!(out.lock().is_empty());
        clock.advance(25_000_000);
        assert_eq!(*out.lock(), vec![0, 0], "released twice (duplicated) once the clock reached 25 ms");
        gate.arrive(&h(1), 10, 1u64);
        gate.arrive(&h(5), 10, 5u64);
        // Message 5's stamp (50 ms) moved the clock past message 1's release (35 ms).
        assert_eq!(*out.lock(), vec![0, 0, 1, 1]);
        let snap = stats.snapshot();
        assert_eq!((snap.injected_delayed, snap.injected_duplicated, snap.injected_dropped), (3, 3, 0));
    }
}
