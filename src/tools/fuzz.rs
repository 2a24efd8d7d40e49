//! `slipstream fuzz`: every decoder and every config parser fed inputs made by mutating valid
//! ones (bit flips, byte and line edits, truncation, splices with other messages, extreme
//! numbers), seeded and repeatable. Each input must come back accepted or rejected with an
//! error: a panic is a finding, counted and shown (its input in hex) and the run fails.
//!
//! Targets: the wire decoder of every message type (the example payloads of
//! docs/wire-format.md mutated, through the same dispatch `echo` and the recorder use), the
//! zero-copy camera frame decoder, the pixel decoders (a frame in LZ4, JPEG and PNG mutated:
//! truncations, mislabelled encodings, sizes that would expand far beyond the bytes), the topic config, a scenario, the ACC settings and a fault profile (their
//! shipped files mutated). The parsers read whole files, thousands a second: they get a count
//! of their own.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

use anyhow::Result;
use serde::Serialize;

use crate::msg::{self, CameraFrameRef, MessageKind};
use crate::sim::SimRng;

const TOPIC_CONFIG: &str = include_str!("../../config/slipstream.json5");
const ACC_SETTINGS: &str = include_str!("../../config/acc.json5");
const SCENARIO: &str = include_str!("../../scenarios/cut-in.json5");
const FAULT_PROFILE: &str = include_str!("../../config/faults/wifi-busy.json5");

/// Values that break naive parsers, spliced into text inputs.
const EXTREMES: &[&str] =
    &["1e309", "-1e309", "NaN", "-0", "18446744073709551616", "-9223372036854775809", "\"\"", "null", "[]", "{}", "0x"];

#[derive(Debug, Clone, Copy, clap::Args)]
#[command(after_help = "Example:\n  slipstream fuzz --count 10000000     (docs/performance.md has the figures)")]
pub struct FuzzArgs {
    /// Inputs per decoder
    #[arg(long, default_value_t = 100_000)]
    pub count: u64,
    /// Inputs per config parser (they parse whole files: thousands a second)
    /// [default: a tenth of --count]
    #[arg(long)]
    pub parser_count: Option<u64>,
    /// Seed of the input generator: the same seed, the same inputs
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
}

/// What one target did.
#[derive(Debug, Clone, Serialize)]
pub struct TargetReport {
    pub target: String,
    pub inputs: u64,
    pub accepted: u64,
    pub rejected: u64,
    pub panics: u64,
    pub seconds: f64,
    pub inputs_per_s: f64,
    /// The first input that panicked, hex, with the panic's message.
    pub first_panic: Option<String>,
}

/// One mutation of `base` (other valid inputs in `others` for splices).
pub(crate) fn mutate(rng: &mut SimRng, base: &[u8], others: &[&[u8]], text: bool) -> Vec<u8> {
    let mut v = base.to_vec();
    let edits = 1 + rng.below(4);
    for _ in 0..edits {
        let at = |rng: &mut SimRng, v: &Vec<u8>| rng.below(v.len() as u64 + 1) as usize;
        match rng.below(if text { 9 } else { 7 }) {
            0 if !v.is_empty() => {
                let i = rng.below(v.len() as u64) as usize;
                v[i] ^= 1 << rng.below(8);
            }
            1 if !v.is_empty() => {
                let i = rng.below(v.len() as u64) as usize;
                v[i] = rng.next_u64() as u8;
            }
            2 => {
                let i = at(rng, &v);
                v.insert(i, rng.next_u64() as u8);
            }
            3 if !v.is_empty() => {
                let i = rng.below(v.len() as u64) as usize;
                let n = (1 + rng.below(8) as usize).min(v.len() - i);
                v.drain(i..i + n);
            }
            4 => v.truncate(at(rng, &v)),
            5 => {
                // Splice: the head of this input, the tail of another.
                let other = others[rng.below(others.len() as u64) as usize];
                let (i, j) = (at(rng, &v), rng.below(other.len() as u64 + 1) as usize);
                v.truncate(i);
                v.extend_from_slice(&other[j..]);
            }
            6 => {
                // Repeat a run (lengths and counts that point past the end).
                let i = at(rng, &v);
                let n = (rng.below(16) as usize).min(v.len() - i);
                let run: Vec<u8> = v[i..i + n].to_vec();
                for _ in 0..1 + rng.below(64) {
                    v.splice(i..i, run.iter().copied());
                }
            }
            7 => {
                // An extreme value where a number may stand.
                let e = EXTREMES[rng.below(EXTREMES.len() as u64) as usize].as_bytes();
                let digits: Vec<usize> = (0..v.len()).filter(|&k| v[k].is_ascii_digit()).collect();
                if let Some(&k) = digits.get(rng.below(digits.len().max(1) as u64) as usize) {
                    let end = (k..v.len()).find(|&m| !v[m].is_ascii_digit() && v[m] != b'.').unwrap_or(v.len());
                    v.splice(k..end, e.iter().copied());
                }
            }
            _ => {
                // Drop or double a line.
                let lines: Vec<usize> = (0..v.len()).filter(|&k| v[k] == b'\n').collect();
                if lines.len() > 2 {
                    let a = lines[rng.below(lines.len() as u64 - 1) as usize];
                    let b = lines.iter().copied().find(|&l| l > a).unwrap_or(v.len());
                    let line: Vec<u8> = v[a..b].to_vec();
                    if rng.below(2) == 0 {
                        v.drain(a..b);
                    } else {
                        v.splice(a..a, line);
                    }
                }
            }
        }
    }
    v
}

/// Feeds `count` mutations of `bases` (spliced with `others`) to `check`: true accepted,
/// false rejected.
fn fuzz(
    name: &str,
    bases: &[&[u8]],
    others: &[&[u8]],
    text: bool,
    count: u64,
    seed: u64,
    check: impl Fn(&[u8]) -> bool,
) -> TargetReport {
    let mut rng = SimRng::new(seed ^ name.bytes().fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b as u64)));
    let mut r = TargetReport {
        target: name.to_string(),
        inputs: 0,
        accepted: 0,
        rejected: 0,
        panics: 0,
        seconds: 0.0,
        inputs_per_s: 0.0,
        first_panic: None,
    };
    let started = Instant::now();
    for _ in 0..count {
        let base = bases[rng.below(bases.len() as u64) as usize];
        let input = mutate(&mut rng, base, others, text);
        r.inputs += 1;
        match catch_unwind(AssertUnwindSafe(|| check(&input))) {
            Ok(true) => r.accepted += 1,
            Ok(false) => r.rejected += 1,
            Err(panic) => {
                r.panics += 1;
                let why = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                r.first_panic.get_or_insert_with(|| format!("{why}: {}", msg::hex_lines(&input).replace('\n', " ")));
            }
        }
    }
    r.seconds = started.elapsed().as_secs_f64();
    r.inputs_per_s = r.inputs as f64 / r.seconds.max(1e-9);
    r
}

/// Runs every target, `count` inputs per decoder and `parser_count` per config parser;
/// panics are caught and counted (their message still goes through the panic hook).
pub fn run(count: u64, parser_count: u64, seed: u64) -> Vec<TargetReport> {
    let examples = msg::examples();
    let all: Vec<&[u8]> = examples.iter().map(|(_, b)| b.as_slice()).collect();
    let mut reports = Vec::new();
    for (kind, bytes) in &examples {
        // The type's own bytes mutated, spliced with any type's.
        let base = [bytes.as_slice()];
        let name = format!("wire: {}", kind.name());
        reports.push(fuzz(&name, &base, &all, false, count, seed, |input| msg::decode_json(input).is_ok()));
        if *kind == MessageKind::CameraFrame {
            reports.push(fuzz("wire: CameraFrame (zero-copy)", &base, &all, false, count, seed, |input| {
                msg::decode::<CameraFrameRef>(input).is_ok()
            }));
        }
    }
    for (encoding, payload) in frame_payloads() {
        let name = format!("pixels: {encoding:?} frame");
        reports.push(fuzz(&name, &[payload.as_slice()], &all, false, count, seed, |input| {
            msg::decode::<CameraFrameRef>(input).is_ok_and(|f| f.msg.to_rgb8().is_ok())
        }));
    }
    let text = |s: &'static str| -> &'static [u8] { s.as_bytes() };
    let (n, as_str) = (parser_count, |b: &[u8]| String::from_utf8_lossy(b).into_owned());
    reports.push(fuzz("config: topic config", &[text(TOPIC_CONFIG)], &[text(TOPIC_CONFIG)], true, n, seed, |b| {
        crate::config::TopicMap::from_json5(&as_str(b), "fuzz").is_ok()
    }));
    reports.push(fuzz("config: scenario", &[text(SCENARIO)], &[text(SCENARIO)], true, n, seed, |b| {
        crate::sim::Scenario::parse(&as_str(b), "fuzz").is_ok()
    }));
    reports.push(fuzz("config: ACC settings", &[text(ACC_SETTINGS)], &[text(ACC_SETTINGS)], true, n, seed, |b| {
        crate::acc::AccSettings::parse(&as_str(b), "fuzz").is_ok()
    }));
    reports.push(fuzz("config: fault profile", &[text(FAULT_PROFILE)], &[text(FAULT_PROFILE)], true, n, seed, |b| {
        crate::config::FaultProfile::parse(&as_str(b), "fuzz", "fuzz").is_ok()
    }));
    reports
}

/// A small frame (40x30, a horizon and a dark box) as a camera/front payload in each
/// compressed encoding.
fn frame_payloads() -> Vec<(msg::ImageEncoding, Vec<u8>)> {
    let (w, h) = (40u32, 30u32);
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            match (y < h / 2, (15..25).contains(&x) && (15..20).contains(&y)) {
                (_, true) => [20, 20, 25],
                (true, _) => [150, 180, 220],
                _ => [90, 90, (x % 7) as u8 + 90],
            }
        })
        .collect();
    [msg::ImageEncoding::Lz4, msg::ImageEncoding::Jpeg, msg::ImageEncoding::Png]
        .into_iter()
        .map(|encoding| {
            let data = msg::encode_pixels(&rgb, w, h, encoding, 85).expect("a valid frame encodes");
            let frame = msg::CameraFrame { width: w, height: h, encoding, data };
            (encoding, msg::encode(&msg::Header::default(), &frame))
        })
        .collect()
}

/// The table people read.
pub fn markdown(reports: &[TargetReport]) -> String {
    let mut s =
        String::from("| target | inputs | accepted | rejected | panics | inputs/s |\n|---|---|---|---|---|---|\n");
    for r in reports {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.0} |\n",
            r.target, r.inputs, r.accepted, r.rejected, r.panics, r.inputs_per_s
        ));
    }
    for r in reports.iter().filter(|r| r.panics > 0) {
        s.push_str(&format!("\n{} panicked: {}\n", r.target, r.first_panic.as_deref().unwrap_or("")));
    }
    s
}

/// `slipstream fuzz`: the table (or JSON); fails when anything panicked.
pub fn command(args: &FuzzArgs) -> Result<std::process::ExitCode> {
    // Panics are findings, shown in the table: not printed once per input meanwhile.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let reports = run(args.count, args.parser_count.unwrap_or(args.count / 10), args.seed);
    std::panic::set_hook(hook);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    } else {
        print!("{}", markdown(&reports));
    }
    let panics: u64 = reports.iter().map(|r| r.panics).sum();
    anyhow::ensure!(panics == 0, "{panics} inputs made a decoder or parser panic (above)");
    Ok(std::process::ExitCode::SUCCESS)
}
