//! `slipstream conform sim`: checks that whatever publishes the simulator's side of the bus
//! (slipstream-sim, the Python reference simulator, a CARLA or CoppeliaSim adapter) keeps the
//! contract the detector, the ACC and the tools rely on (docs/simulator-contract.md).
//!
//! # Layout
//! - observed.rs: what was seen, as plain data;
//! - watch.rs: the bus side (subscriptions, the late subscriber, the control probe, lockstep
//!   answers), every wait bounded;
//! - rules.rs: the contract's rules judged from what was seen;
//! - node.rs: `conform controller` and `conform detector`, a node of the user's own in its
//!   role of a short lockstep loop, its answers judged against the node contract.

pub mod node;
pub mod observed;
pub mod rules;
pub mod watch;

use serde::Serialize;

pub use rules::{failed, judge, Outcome, Verdict};

/// `slipstream conform`: the contracts a component can be checked against.
#[derive(clap::Subcommand, Debug)]
pub enum ConformCommand {
    /// Check a running simulator against the simulator contract (docs/simulator-contract.md)
    ///
    /// Joins the bus beside the simulator (same connection flags and -n/--namespace as the
    /// loop), watches every key of the contract for --duration, then, in realtime or fast
    /// mode, sends a gentle brake (0.3125) on vehicle/control for up to 1 s and checks that
    /// vehicle/state shows it applied; with --lockstep it answers every step instead, as the
    /// node the simulator's lockstep waits for. Prints one line per rule, PASS, FAIL or SKIP
    /// with the numbers, and exits with 1 on any FAIL. Run it with the simulator alone (no
    /// ACC driving it). Examples:
    ///
    ///   slipstream-sim --mode realtime &   slipstream conform sim
    ///   slipstream-sim --mode lockstep &   slipstream conform sim --lockstep
    ///   slipstream -n car1 -e tcp/ROUTER:7447 conform sim --json
    #[command(verbatim_doc_comment)]
    Sim(ConformSimArgs),
    /// Check a controller of your own against the controller contract (docs/node-contract.md)
    ///
    /// Starts the command as the controller of a short lockstep loop beside slipstream-sim
    /// (ground truth; loopback ports and a namespace of its own) and judges every answer: its
    /// token before the first step, one answer per state naming its step, the state's stamp
    /// copied, the node's name attached, pedals within 0..1, acc/status published. Without
    /// --command it checks the controller already running (its token nodes/acc) in the
    /// namespace (-n) on the connection (-e/-l), the simulator started here. Prints one
    /// line per rule and exits with 1 on any FAIL. Examples:
    ///
    ///   slipstream conform controller --command 'python3 clients/python/examples/own_acc.py'
    ///   own-controller -n mine --name acc -l tcp/127.0.0.1:7450 &   slipstream -n mine -e tcp/127.0.0.1:7450 conform controller
    #[command(verbatim_doc_comment)]
    Controller(node::ConformNodeArgs),
    /// Check a detector of your own against the detector contract (docs/node-contract.md)
    ///
    /// Starts the command as the detector of a short lockstep loop beside slipstream-sim and
    /// slipstream-acc (camera perception) and judges every answer: its token before the first
    /// step, one perception/objects per frame, the frame's stamp copied, frame_seq rising,
    /// the node's name attached. Without --command it checks the detector already running
    /// (its token nodes/detect) in the namespace (-n) on the connection (-e/-l). Example:
    ///
    ///   slipstream conform detector --command 'python3 clients/python/examples/own_detect.py'
    #[command(verbatim_doc_comment)]
    Detector(node::ConformNodeArgs),
}

#[derive(clap::Args, Debug, Clone)]
pub struct ConformSimArgs {
    /// Wall-clock seconds to watch (after the first message), at most an hour (what is seen
    /// is kept to be judged)
    #[arg(long, default_value_t = 5.0, value_parser = up_to_an_hour)]
    pub duration: f64,
    /// Seconds to wait for the simulator's first message before judging
    #[arg(long, default_value_t = 10.0, value_parser = up_to_an_hour)]
    pub wait: f64,
    /// Answer every step as the controller a lockstep simulator waits for (node --as)
    #[arg(long)]
    pub lockstep: bool,
    /// The node name to answer as in lockstep: one the simulator's lockstep.wait_for lists
    #[arg(long = "as", value_name = "NODE", default_value = "acc")]
    pub name: String,
    /// Do not send the control probe (the control rule is then skipped)
    #[arg(long)]
    pub no_control: bool,
    /// Print the verdicts as JSON
    #[arg(long)]
    pub json: bool,
}

fn up_to_an_hour(s: &str) -> Result<f64, String> {
    super::top::positive(s).and_then(|v| match v <= 3600.0 {
        true => Ok(v),
        false => Err(format!("`{s}` s is more than an hour: watch at most 3600 s")),
    })
}

/// The result of one `conform sim`.
#[derive(Debug, Clone, Serialize)]
pub struct ConformReport {
    /// What was checked: the simulator, a controller or a detector.
    pub subject: &'static str,
    pub namespace: String,
    pub lockstep: bool,
    pub window_s: f64,
    pub pass: bool,
    pub verdicts: Vec<Verdict>,
}

/// Watches the simulator on `bus` and judges it.
pub async fn run_sim(bus: &crate::Bus, args: &ConformSimArgs) -> Result<ConformReport, crate::bus::BusError> {
    let observed = watch::watch(bus, args).await?;
    let verdicts = judge(&observed);
    Ok(ConformReport {
        subject: "simulator",
        namespace: bus.topics().namespace().to_string(),
        lockstep: args.lockstep,
        window_s: observed.window_s,
        pass: !failed(&verdicts),
        verdicts,
    })
}

/// The verdicts as a table, one rule a line.
pub fn render(report: &ConformReport) -> String {
    let width = report.verdicts.iter().map(|v| v.rule.len()).max().unwrap_or(0);
    let mut out = String::new();
    for v in &report.verdicts {
        let outcome = match v.outcome {
            Outcome::Pass => "PASS",
            Outcome::Fail => "FAIL",
            Outcome::Skip => "skip",
        };
        out += &format!("{outcome}  {:width$}  {}\n", v.rule, v.detail);
    }
    let count = |o: Outcome| report.verdicts.iter().filter(|v| v.outcome == o).count();
    let ns = if report.namespace.is_empty() {
        "no namespace".to_string()
    } else {
        format!("namespace '{}'", report.namespace)
    };
    out += &format!(
        "{} passed, {} failed, {} skipped ({ns}, {:.1} s watched): the {} {} the contract\n",
        count(Outcome::Pass),
        count(Outcome::Fail),
        count(Outcome::Skip),
        report.window_s,
        report.subject,
        if report.pass { "keeps" } else { "breaks" }
    );
    out
}

/// `slipstream conform sim`: as the lockstep node it answers for, or as a watcher of its own
/// name; the verdicts (or JSON), and exit 1 when a rule failed.
pub fn command(command: &ConformCommand, connect: &crate::ConnectArgs) -> anyhow::Result<std::process::ExitCode> {
    let args = match command {
        ConformCommand::Sim(args) => args,
        ConformCommand::Controller(a) => return node_command(node::Role::Controller, a, connect),
        ConformCommand::Detector(a) => return node_command(node::Role::Detector, a, connect),
    };
    let node = if args.lockstep { args.name.clone() } else { crate::cli::own_name("conform") };
    // The verdict is printed while still on the bus: leaving it can neither delay nor lose it.
    let pass = crate::cli::on_bus(connect, &node, |bus| async move {
        let report = run_sim(&bus, args).await?;
        crate::cli::print_report(args.json, &report, render)?;
        Ok(report.pass)
    })?;
    Ok(crate::cli::exit_when(pass))
}

/// `conform controller` / `conform detector`: the verdicts (or JSON), exit 1 when a rule failed.
fn node_command(
    role: node::Role,
    args: &node::ConformNodeArgs,
    connect: &crate::ConnectArgs,
) -> anyhow::Result<std::process::ExitCode> {
    let report = tokio::runtime::Runtime::new()?.block_on(node::run_node(role, args, connect))?;
    crate::cli::print_report(args.json, &report, render)?;
    Ok(crate::cli::exit_when(report.pass))
}
