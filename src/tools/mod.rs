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

/// A default output path of its own: `<stem>-<UTC stamp><ext>`, or with `-2`, `-3`, ... when
/// another run took that name in the same second (two `up` started together write two
/// reports, never one over the other). `create` makes the path (a directory, an empty file)
/// and fails when it exists, so the claim cannot race.
pub(crate) fn fresh_path(
    parent: &std::path::Path,
    stem: &str,
    ext: &str,
    create: impl Fn(&std::path::Path) -> std::io::Result<()>,
) -> anyhow::Result<std::path::PathBuf> {
    use anyhow::Context;
    if !parent.as_os_str().is_empty() {
        std::fs::create_dir_all(parent).with_context(|| format!("create {}", parent.display()))?;
    }
    let base = format!("{stem}-{}", utc_stamp());
    for n in 1..=1000 {
        let name = if n == 1 { format!("{base}{ext}") } else { format!("{base}-{n}{ext}") };
        let path = parent.join(name);
        match create(&path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("create {}", path.display())),
        }
    }
    anyhow::bail!("{}: a thousand runs named {base} already (fix: name the output yourself)", parent.display())
}

/// [`fresh_path`] for a report directory under `reports/`.
pub(crate) fn fresh_report_dir(stem: &str) -> anyhow::Result<std::path::PathBuf> {
    fresh_path(std::path::Path::new("reports"), stem, "", |p| std::fs::create_dir(p))
}

/// [`fresh_path`] for a recording in the working directory.
pub(crate) fn fresh_recording() -> anyhow::Result<std::path::PathBuf> {
    fresh_path(std::path::Path::new(""), "recording", ".mcap", |p| {
        std::fs::OpenOptions::new().write(true).create_new(true).open(p).map(drop)
    })
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

    #[test]
    fn two_runs_in_the_same_second_get_two_paths() {
        let parent = std::env::temp_dir().join(format!("fresh-path-{}", std::process::id()));
        let mkdir = |p: &std::path::Path| std::fs::create_dir(p);
        let first = super::fresh_path(&parent, "cut-in", "", mkdir).unwrap();
        let second = super::fresh_path(&parent, "cut-in", "", mkdir).unwrap();
        assert_ne!(first, second);
        assert!(first.is_dir() && second.is_dir());
        // The second name is the first's with -2, unless the clock turned a second between.
        let (a, b) = (first.display().to_string(), second.display().to_string());
        assert!(b == format!("{a}-2") || b > a, "{a} then {b}");
        std::fs::remove_dir_all(&parent).unwrap();
    }
}
