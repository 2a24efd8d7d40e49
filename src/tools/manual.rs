//! `slipstream completions SHELL` and `slipstream man DIR`: shell completion scripts and man
//! pages generated from the command line's own definition, so they never drift from `--help`.

use std::process::ExitCode;

use anyhow::{Context, Result};

/// The completion script of `shell` for the command `cli` on stdout. A reader that stops early
/// (`| head`) ends it quietly, as it would `cat`.
pub fn completions(mut cli: clap::Command, shell: clap_complete::Shell) -> Result<ExitCode> {
    use std::io::Write;
    let name = cli.get_name().to_string();
    let mut script = Vec::new();
    clap_complete::generate(shell, &mut cli, name, &mut script);
    match std::io::stdout().lock().write_all(&script) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(ExitCode::SUCCESS),
    }
}

/// The page of `top` (slipstream.1) and one per visible command (slipstream-up.1, ...) into
/// `dir`.
pub fn man_pages(top: clap::Command, dir: &std::path::Path) -> Result<ExitCode> {
    std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    let pages = std::iter::once(top.clone()).chain(
        top.get_subcommands()
            .filter(|c| !c.is_hide_set())
            .map(|c| c.clone().name(format!("{}-{}", top.get_name(), c.get_name())))
            .collect::<Vec<_>>(),
    );
    for page in pages {
        let path = dir.join(format!("{}.1", page.get_name()));
        let mut text = Vec::new();
        clap_mangen::Man::new(page).render(&mut text)?;
        std::fs::write(&path, text).with_context(|| format!("write {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}
