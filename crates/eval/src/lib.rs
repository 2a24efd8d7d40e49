//! Judging runs of the loop. What a run recorded, the figures and plots made
//! from it, and the suites that score the detector and the ACC.
//!
//! One path from a run to its figures, whichever way the loop ran (`slipstream up`, `eval acc`,
//! the in-process loop of the tests): [`trace::Recorder`] (or the in-process loop) ->
//! [`trace::Trace`] -> [`metrics::Metrics`] and [`plot`]. The loop's latency per hop comes from
//! the message stamps ([`latency`]).
//!
//! # Layout
//! - [`trace`]: the recorder of a run on the bus and the trace built from it (one sample per
//!   vehicle/state with the ACC's status and the true lead); trace.csv.
//! - [`metrics`]: the ACC's figures against ground truth and its aims.
//! - [`judge`]: a finished run judged (recording -> trace -> metrics), the one tail of `up`
//!   and `eval acc`.
//! - [`latency`]: the loop's latency hop by hop from the message stamps; the string-stability
//!   bound.
//! - [`plot`]: PNG plots of a trace and of the loop latency.
//! - [`acc`]: `slipstream eval acc`, the scenario suite over separate processes (through
//!   [`slipstream_launch`]); [`egos`]: a run with several controlled vehicles judged car by car.
//! - [`sweep`]: `slipstream eval sweep`, generated scenarios by the thousand, judged as
//!   rates per 1,000 km (runs of [`acc`]).
//! - [`faults`]: `slipstream eval faults`, the ACC's safety envelope under injected network
//!   faults (runs of [`acc`] with fault profiles).
//! - [`detect`]: `slipstream eval detect`, the detector scored against ground truth, in process;
//!   [`bend_lateral`]: its lateral error far ahead by range and bend.
//! - `offline` (tests only): the closed loop in one process without the bus.
//! - [`resim`]: a recording in place of the simulator: today's detector and ACC answer the
//!   recorded inputs, and their outputs are compared with the recorded ones (`up --from`).

pub mod acc;
pub(crate) mod bend_lateral;
pub mod detect;
pub(crate) mod detect_remote;
pub mod egos;
pub mod error;
pub mod faults;
pub(crate) mod frame_detector;
pub mod judge;
pub mod link_codec;
pub(crate) mod metrics;
#[cfg(test)]
pub(crate) mod offline;
pub mod platoon;
pub mod plot;
pub mod resim;
pub mod sweep;
pub mod trace;

pub use bend_lateral::LateralCell;
pub use error::{Error, Result};
pub use metrics::{Check, Metrics};
pub use trace::{Recorder, Trace};

/// An optional figure with `digits` decimals, or "-" (tables of `eval`, `bench`, `up`, `top`).
pub fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}
