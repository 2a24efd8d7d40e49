//! What a long-running tool shows on stderr while it works. On a terminal: one block redrawn in
//! place (`indicatif`), and for counted work a bar with the time left. Anywhere else (a pipe, a
//! log file, CI, `--plain`): a line per update, so a log reads top to bottom with no control
//! characters in it. A log line written while a status is live goes above it
//! ([`write_above`]), never into the middle of it.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How often the bar redraws at most on its own (the elapsed time and rate move).
const TICK: Duration = Duration::from_millis(500);

/// The status being redrawn in place, if any: log lines are written above it.
static LIVE: std::sync::Mutex<Option<ProgressBar>> = std::sync::Mutex::new(None);

/// Writes `bytes` (whole log lines) to stderr: above the live status when one is drawn (it is
/// cleared, the lines written, and it is drawn again), else straight through.
pub fn write_above(bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let live = LIVE.lock().ok().and_then(|l| l.clone());
    match live {
        Some(bar) => bar.suspend(|| std::io::stderr().lock().write_all(bytes)),
        None => std::io::stderr().lock().write_all(bytes),
    }
}

/// Makes `bar` the live status (or none).
fn set_live(bar: Option<&ProgressBar>) {
    if let Ok(mut l) = LIVE.lock() {
        *l = bar.cloned();
    }
}

/// A tool's live status line(s) or bar.
pub struct Status {
    bar: Option<ProgressBar>,
}

impl Status {
    /// A block of text redrawn in place on a terminal (unless `plain`), else printed as lines.
    pub fn lines(plain: bool) -> Status {
        Status::new(live(plain).then(|| bar(None, "{msg}")))
    }

    /// `len` steps with a bar, the count, the time spent and the time left at the pace so far.
    pub fn counted(len: u64, plain: bool) -> Status {
        let template = "{bar:32} {pos}/{len} [{elapsed_precise}, ~{eta} left] {msg}";
        Status::new(live(plain).then(|| bar(Some(len), template)))
    }

    fn new(bar: Option<ProgressBar>) -> Status {
        if bar.is_some() {
            set_live(bar.as_ref());
        }
        Status { bar }
    }

    /// Whether the status is redrawn in place (a terminal) rather than printed as lines.
    pub fn is_live(&self) -> bool {
        self.bar.is_some()
    }

    /// Shows `text` (one or more lines): in place of the last, or as new lines.
    pub fn show(&self, text: &str) {
        match &self.bar {
            Some(b) => b.set_message(text.to_string()),
            None => eprintln!("{text}"),
        }
    }

    /// The number of steps, once it is known.
    pub fn set_total(&self, len: u64) {
        if let Some(b) = &self.bar {
            b.set_length(len);
        }
    }

    /// One more step of counted work done.
    pub fn step(&self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }

    /// A line that stays: above the live block on a terminal, else a plain line.
    pub fn note(&self, line: &str) {
        match &self.bar {
            Some(b) => b.println(line),
            None => eprintln!("{line}"),
        }
    }

    /// Leaves the last state drawn (a terminal) and ends the redrawing.
    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
            set_live(None);
        }
    }
}

impl Drop for Status {
    fn drop(&mut self) {
        self.finish();
    }
}

fn live(plain: bool) -> bool {
    !plain && std::io::stderr().is_terminal()
}

fn bar(len: Option<u64>, template: &str) -> ProgressBar {
    let b = ProgressBar::with_draw_target(len, ProgressDrawTarget::stderr());
    // The templates are constants of this file, checked by its tests.
    if let Ok(style) = ProgressStyle::with_template(template) {
        b.set_style(style.progress_chars("=> "));
    }
    b.enable_steady_tick(TICK);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_templates_parse() {
        for t in ["{msg}", "{bar:32} {pos}/{len} [{elapsed_precise}, ~{eta} left] {msg}"] {
            assert!(ProgressStyle::with_template(t).is_ok(), "{t}");
        }
    }

    #[test]
    fn plain_status_is_not_live() {
        assert!(!Status::lines(true).is_live());
        assert!(!Status::counted(10, true).is_live());
    }
}
