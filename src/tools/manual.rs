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

/// The page of `top` (slipstream.1), one per visible command at every depth (slipstream-up.1,
/// slipstream-eval-acc.1, ...) and one per node binary (slipstream-sim.1, ...) into `dir`.
pub fn man_pages(top: clap::Command, dir: &std::path::Path) -> Result<ExitCode> {
    std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    let mut pages = Vec::new();
    for command in std::iter::once(top).chain(node_commands()) {
        collect_pages(command, &mut pages);
    }
    for page in pages {
        let path = dir.join(format!("{}.1", page.get_name()));
        let mut text = Vec::new();
        clap_mangen::Man::new(page).render(&mut text)?;
        std::fs::write(&path, text).with_context(|| format!("write {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The node binaries' command lines.
fn node_commands() -> Vec<clap::Command> {
    use crate::{acc::args::AccCli, perception::args::DetectCli, sim::args::SimCli};
    use clap::CommandFactory;
    vec![SimCli::command(), DetectCli::command(), AccCli::command()]
}

/// `command`'s page and, named `<command>-<sub>`, its visible subcommands' pages, at every depth.
fn collect_pages(command: clap::Command, pages: &mut Vec<clap::Command>) {
    let name = command.get_name().to_string();
    let subs: Vec<clap::Command> = command
        .get_subcommands()
        .filter(|c| !c.is_hide_set() && c.get_name() != "help")
        .map(|c| c.clone().name(format!("{name}-{}", c.get_name())))
        .collect();
    pages.push(command);
    for sub in subs {
        collect_pages(sub, pages);
    }
}
