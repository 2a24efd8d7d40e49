//! `slipstream convert IN.mcap --to ros2 OUT.mcap`: a slipstream recording (`record`, `up
//! --record`) as a `ros2`-profile MCAP file, the ROS 2 messages of the `ros2` mapping in CDR,
//! made by the same translator as the live bridge. Log times are kept as recorded.

use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::PathBuf;

use anyhow::{Context as _, Result};
use serde::Serialize;

use crate::config::TopicMap;
use crate::ros2::mapping::Direction;
use crate::ros2::translate::Translator;
use crate::ros2::{Bag, Ros2Config, Route};
use crate::topics::Topic;

#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  slipstream convert reports/RUN/run.mcap --to ros2 run-ros2.mcap\n  \
    ros2 bag play run-ros2.mcap   (on a ROS 2 machine)")]
pub struct ConvertArgs {
    /// A slipstream recording
    #[arg(value_name = "IN.mcap")]
    pub input: PathBuf,
    /// The profile to convert to
    #[arg(long, value_enum)]
    pub to: Target,
    /// The file to write
    #[arg(value_name = "OUT.mcap")]
    pub output: PathBuf,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Target {
    Ros2,
}

/// What a conversion read and wrote.
#[derive(Debug, Default, Serialize)]
pub struct ConvertSummary {
    pub read: u64,
    pub written: u64,
    /// Messages of keys no route takes (sim/events, vehicle/speed, ...).
    pub unmapped: u64,
    /// Payloads that did not decode as their topic's message.
    pub malformed: u64,
    /// Whether the input was cut (read up to its last whole chunk).
    pub input_cut: bool,
}

/// The recording's namespace, from its channels' metadata.
fn namespace_of(channel: &mcap::Channel) -> String {
    channel.metadata.get("namespace").cloned().unwrap_or_default()
}

/// Converts `input` into `output` with the mapping of `topics`.
pub fn run(args: &ConvertArgs, topics: &TopicMap) -> Result<ConvertSummary> {
    anyhow::ensure!(args.input.is_file(), "{} is no file (a slipstream recording)", args.input.display());
    let config = Ros2Config::from_topic_map(topics)?;
    let bag = Bag::create(&args.output, &config)?;
    let mut summary = ConvertSummary::default();
    let mut keys: HashMap<String, Option<(Topic, String)>> = HashMap::new();
    // One translator per vehicle: /tf_static gathers its cameras' mounts.
    let mut translators: HashMap<String, Translator> = HashMap::new();
    let routes: Vec<Route> =
        config.enabled().filter(|(r, _)| r.direction() == Direction::ToRos).map(|(r, _)| r).collect();
    let types: Vec<(Route, &str)> = config.enabled().map(|(r, e)| (r, e.type_name.as_str())).collect();
    // The bag's failure stops the reading and is kept here: the reader's own errors are the
    // recording's.
    let mut failed = None;
    summary.input_cut = crate::record::each_message_until(&args.input, |m| {
        summary.read += 1;
        let found = keys.entry(m.channel.topic.clone()).or_insert_with(|| topic_of(topics, &m.channel));
        let Some((topic, ns)) = found else {
            summary.unmapped += 1;
            return Ok(ControlFlow::Continue(()));
        };
        let translator = translators.entry(ns.clone()).or_insert_with(|| Translator::new(ns).with_types(types.clone()));
        let fed: Vec<Route> = routes.iter().copied().filter(|r| r.sources().contains(topic)).collect();
        if fed.is_empty() {
            summary.unmapped += 1;
        }
        for route in fed {
            match translator.encode(route, *topic, &m.data) {
                Ok(Some((header, cdr))) => {
                    if let Err(e) = bag.write(route, &header, m.log_time, &cdr) {
                        failed = Some(e);
                        return Ok(ControlFlow::Break(()));
                    }
                    summary.written += 1;
                }
                Ok(None) => {}
                Err(e) => {
                    summary.malformed += 1;
                    tracing::debug!(key = %m.channel.topic, "not converted: {e}");
                }
            }
        }
        Ok(ControlFlow::Continue(()))
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    bag.finish()?;
    Ok(summary)
}

/// The topic a recorded key carries, under the recording's namespace and `topics`' remapping;
/// None for keys of no topic. The payload's kind is checked when it is converted.
fn topic_of(topics: &TopicMap, channel: &mcap::Channel) -> Option<(Topic, String)> {
    let ns = namespace_of(channel);
    let map = topics.clone().with_namespace(&ns).ok()?;
    let topic = Topic::ALL.into_iter().find(|t| map.key(*t).as_str() == channel.topic)?;
    Some((topic, ns))
}

/// `slipstream convert`: converts and prints the summary; exit 1 when a payload did not
/// convert.
pub fn command(args: &ConvertArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    let s = run(args, &connect.topic_map()?).with_context(|| format!("convert {}", args.input.display()))?;
    println!(
        "{}: {} messages read, {} ROS 2 messages written to {}; {} on keys no route takes, {} malformed{}",
        args.input.display(),
        s.read,
        s.written,
        args.output.display(),
        s.unmapped,
        s.malformed,
        if s.input_cut { " (the input was cut; read up to its last whole chunk)" } else { "" }
    );
    Ok(crate::cli::exit_when(s.malformed == 0))
}
