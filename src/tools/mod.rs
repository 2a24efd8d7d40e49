//! The `slipstream` command's tools that are not benchmarks: `up` (the whole loop, through the
//! launch and eval layers), `record`, `play`, `view`, `ros2`, `conform`, `top`, `echo`, `info`, `demo`, `router`,
//! `soak`.

pub mod conform;
pub mod convert;
pub mod demo;
pub mod echo;
pub mod eval;
pub mod fuzz;
pub mod info;
pub mod manual;
pub mod play;
pub mod record;
pub mod ros2;
pub mod router;
pub mod soak;
pub mod status;
pub mod top;
pub mod up;
pub mod view;
pub mod wire;

/// Waits for a stop request (Ctrl-C, SIGTERM, SIGHUP: [`crate::cli::stop_requested`]) or
/// `duration_s`, showing `status()` on stderr every `every` ([`status::Status`]: redrawn in
/// place on a terminal, a line each otherwise) (`record`, `view`, `ros2`).
pub(crate) async fn until_stopped(
    duration_s: Option<f64>,
    every: std::time::Duration,
    mut status: impl FnMut() -> String,
) {
    use std::time::{Duration, Instant};
    let shown = status::Status::lines(false);
    let deadline = duration_s.map(|d| Instant::now() + Duration::from_secs_f64(d));
    let ctrl_c = crate::cli::stop_requested();
    tokio::pin!(ctrl_c);
    let mut tick = tokio::time::interval(every);
    loop {
        let left = deadline.map_or(Duration::from_secs(3600), |d| d.saturating_duration_since(Instant::now()));
        tokio::select! {
            _ = &mut ctrl_c => break,
            _ = tokio::time::sleep(left) => if deadline.is_some() { break },
            _ = tick.tick() => shown.show(&status()),
        }
    }
    shown.finish();
}

/// UTC date and time for directory names: 20261122-041530.
pub(crate) fn utc_stamp() -> String {
    jiff::Timestamp::now().strftime("%Y%m%d-%H%M%S").to_string()
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_stamp_has_the_shape_of_a_date() {
        let s = super::utc_stamp();
        assert_eq!(s.len(), 15, "{s}");
        assert!(s.starts_with("20"), "{s}");
        let month: u32 = s[4..6].parse().unwrap();
        let day: u32 = s[6..8].parse().unwrap();
        assert!((1..=12).contains(&month) && (1..=31).contains(&day), "{s}");
    }
}
