//! A recording the page can move through: what the view needs of a replay (play, pause, move,
//! where it is), so that the view does not depend on how recordings are read
//! (record::Replay implements it).

use serde::Serialize;

/// Where a replay is, as the page shows it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Position {
    /// Simulated seconds (the messages' stamps) played to.
    pub t_s: f64,
    /// The recording's length in simulated seconds (none when no payload carries a stamp).
    pub duration_s: Option<f64>,
    pub playing: bool,
    /// Simulated seconds played per second.
    pub rate: f64,
}

/// A replay under the page's control.
pub trait Timeline: Send + Sync {
    fn position(&self) -> Position;
    /// Play (true) or pause (false).
    fn play(&self, playing: bool);
    /// Move to `t_s` simulated seconds (clamped to the recording).
    fn seek(&self, t_s: f64);
    /// Play `rate` simulated seconds per second (clamped to what the replay takes).
    fn set_rate(&self, rate: f64);
}
