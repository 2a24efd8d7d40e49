//! A recording the page can move through: what the view needs of a replay (play, pause, move,
//! where it is), so that the view does not depend on how recordings are read
//! (record::Replay implements it).

use serde::Serialize;

/// Where a replay is, as the page shows it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Position {
    /// Seconds since the recording's first message.
    pub t_s: f64,
    /// The recording's length (from its summary; none for a file cut short, which has none).
    pub duration_s: Option<f64>,
    pub playing: bool,
}

/// A replay under the page's control.
pub trait Timeline: Send + Sync {
    fn position(&self) -> Position;
    /// Play (true) or pause (false).
    fn play(&self, playing: bool);
    /// Move to `t_s` seconds from the start (clamped to the recording).
    fn seek(&self, t_s: f64);
}
