//! A recording replayed under a person's hand: played onto a bus at the recorded pace, paused,
//! resumed and moved to any time, as the view's page asks (`slipstream view FILE.mcap`). The
//! view only knows the [`Timeline`] it controls; playing stays here with the other readers of
//! recordings.
//!
//! One thread plays: it reads the file from the start to the time asked (MCAP is read in file
//! order, so a move back reads from the start again, a move ahead reads on), then publishes at
//! the pace of the simulated time the messages carry (their headers' stamp_sim_ns), times the
//! rate the page asks, while the control says play. Simulated time, not the recorder's clock:
//! a lockstep run of 60 s simulated may have been recorded in 10 s of wall time, and a person
//! watches the 60 s. The replay waits for the page: it starts paused, and the page's first
//! request plays it. Pausing holds it between two messages; a new rate goes on from where it is.

use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::play::{each_message_until, output_for, Output};
use crate::error::{Error, Result};
use parking_lot::{Condvar, Mutex};
use slipstream_contract::bus::Bus;
use slipstream_view::{Position, Timeline};

#[derive(Debug)]
struct Control {
    playing: bool,
    /// Simulated seconds played to.
    t_s: f64,
    /// Simulated seconds per second of wall time.
    rate: f64,
    /// A move asked for and not yet made.
    seek_s: Option<f64>,
    stop: bool,
}

/// A recording played onto a bus under control; dropping it stops the thread.
pub struct Replay {
    path: PathBuf,
    duration_s: Option<f64>,
    control: Mutex<Control>,
    changed: Condvar,
}

impl Replay {
    /// Readies `path` for playing onto `bus` from its start, paused until asked to play.
    pub fn start(bus: Arc<Bus>, path: &Path) -> Result<Arc<Replay>> {
        let duration_s = duration_of(path)?;
        let replay = Arc::new(Replay {
            path: path.to_path_buf(),
            duration_s,
            control: Mutex::new(Control { playing: false, t_s: 0.0, rate: 1.0, seek_s: Some(0.0), stop: false }),
            changed: Condvar::new(),
        });
        let r = replay.clone();
        std::thread::Builder::new()
            .name("replay".into())
            .spawn(move || {
                if let Err(e) = r.run(&bus) {
                    tracing::error!("replay of {} stopped: {e}", r.path.display());
                }
            })
            .map_err(|source| Error::System { what: "start the replay's thread".into(), source })?;
        Ok(replay)
    }

    /// Stops the replay's thread (the bus stays open).
    pub fn stop(&self) {
        self.control.lock().stop = true;
        self.changed.notify_all();
    }

    /// Plays passes until stopped: each from the time asked to a move, a stop or the end.
    fn run(&self, bus: &Bus) -> Result<()> {
        let mut outputs = HashMap::new();
        loop {
            let from_s = {
                let mut c = self.control.lock();
                while !c.stop && c.seek_s.is_none() && !c.playing {
                    self.changed.wait(&mut c);
                }
                if c.stop {
                    return Ok(());
                }
                let from = c.seek_s.take().unwrap_or(c.t_s);
                c.t_s = from;
                from
            };
            let ended = self.pass(bus, from_s, &mut outputs)?;
            if ended {
                let mut c = self.control.lock();
                if c.seek_s.is_none() {
                    c.playing = false;
                }
            }
        }
    }

    /// One pass from `from_s`: true when it reached the end of the file. `outputs` (a
    /// publisher per recorded channel) outlive the pass.
    fn pass(&self, bus: &Bus, from_s: f64, outputs: &mut HashMap<u16, Option<Output>>) -> Result<bool> {
        let rate = self.control.lock().rate;
        // Simulated time of the messages so far: it never goes back (the recorder receives each
        // key on its own path, so a message can sit in the file a little behind another key's).
        let mut t_s = 0.0f64;
        // Wall time at which simulated time `from_s` plays; moved on by pauses.
        let mut origin = Instant::now();
        let mut reached_end = true;
        each_message_until(&self.path, |message| {
            t_s = sim_time_s(&message.data).map_or(t_s, |t| t.max(t_s));
            if t_s < from_s {
                return Ok(ControlFlow::Continue(()));
            }
            match self.wait_due(origin + Duration::from_secs_f64((t_s - from_s) / rate)) {
                Due::Now => {}
                Due::Resumed(paused) => origin += paused,
                Due::Leave => {
                    reached_end = false;
                    return Ok(ControlFlow::Break(()));
                }
            }
            if let std::collections::hash_map::Entry::Vacant(e) = outputs.entry(message.channel.id) {
                e.insert(output_for(bus, &message.channel, &[], false)?);
            }
            if let Some(Some(output)) = outputs.get(&message.channel.id) {
                output.put(message.data.into_owned())?;
            }
            self.control.lock().t_s = t_s;
            Ok(ControlFlow::Continue(()))
        })?;
        Ok(reached_end)
    }

    /// Waits until `due` while playing; holds while paused.
    fn wait_due(&self, due: Instant) -> Due {
        let mut c = self.control.lock();
        let mut paused = Duration::ZERO;
        loop {
            if c.stop || c.seek_s.is_some() {
                return Due::Leave;
            }
            if !c.playing {
                let since = Instant::now();
                self.changed.wait(&mut c);
                paused += since.elapsed();
                continue;
            }
            let now = Instant::now();
            if now >= due + paused {
                return if paused.is_zero() { Due::Now } else { Due::Resumed(paused) };
            }
            self.changed.wait_for(&mut c, due + paused - now);
        }
    }
}

enum Due {
    Now,
    /// Playing again after a pause this long.
    Resumed(Duration),
    /// A move or a stop: end this pass.
    Leave,
}

impl Timeline for Replay {
    fn position(&self) -> Position {
        let c = self.control.lock();
        Position { t_s: c.seek_s.unwrap_or(c.t_s), duration_s: self.duration_s, playing: c.playing, rate: c.rate }
    }

    fn set_rate(&self, rate: f64) {
        let mut c = self.control.lock();
        if rate.is_finite() && rate > 0.0 && rate != c.rate {
            c.rate = rate.clamp(MIN_RATE, MAX_RATE);
            // The pass paces at the rate it started with: go on from here at the new one.
            let here = c.t_s;
            c.seek_s.get_or_insert(here);
            self.changed.notify_all();
        }
    }

    fn play(&self, playing: bool) {
        let mut c = self.control.lock();
        // Play at the end starts over.
        if playing && !c.playing && self.duration_s.is_some_and(|d| c.t_s >= d - 0.05) {
            c.seek_s = Some(0.0);
        }
        c.playing = playing;
        self.changed.notify_all();
    }

    fn seek(&self, t_s: f64) {
        let mut c = self.control.lock();
        let end = self.duration_s.unwrap_or(f64::INFINITY);
        c.seek_s = Some(t_s.clamp(0.0, end));
        self.changed.notify_all();
    }
}

impl Drop for Replay {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A bus nobody else joins (no listener, no peer, no scouting): the replay and the view that
/// shows it, in one process.
pub async fn private_bus(node: &str) -> Result<Bus> {
    let mut config = zenoh::Config::from_json5(slipstream_contract::config::DEFAULT_ZENOH_CONFIG)
        .map_err(Error::zenoh("the built-in Zenoh configuration"))?;
    for (key, value) in [
        ("listen/endpoints", "[]"),
        ("connect/endpoints", "[]"),
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "false"),
    ] {
        config.insert_json5(key, value).map_err(Error::zenoh(format!("zenoh config key {key}")))?;
    }
    Ok(Bus::open(config, slipstream_contract::TopicMap::default(), node).await?)
}

/// The slowest and fastest rate the page may ask.
const MIN_RATE: f64 = 0.1;
const MAX_RATE: f64 = 16.0;

/// The simulated time a payload carries (its header's stamp), seconds; none for a payload that
/// is no message of slipstream's.
fn sim_time_s(payload: &[u8]) -> Option<f64> {
    let kind = slipstream_contract::msg::peek_kind(payload).ok()?;
    let (header, _) = slipstream_contract::msg::decode_header(payload, kind).ok()?;
    Some(header.stamp_sim_ns as f64 / 1e9)
}

/// The recording's length in simulated time: the latest stamp its payloads carry (the file is
/// read once, headers only); none when it holds none.
fn duration_of(path: &Path) -> Result<Option<f64>> {
    let mut latest: Option<f64> = None;
    each_message_until(path, |m| {
        if let Some(t) = sim_time_s(&m.data) {
            latest = Some(latest.map_or(t, |l| l.max(t)));
        }
        Ok(ControlFlow::Continue(()))
    })?;
    Ok(latest)
}
