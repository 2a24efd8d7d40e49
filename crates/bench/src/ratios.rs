//! The ratios of the point-to-point tables, each between two rows of the same run found by
//! their typed ids. A ratio whose table ran but whose row did not is reported as missing,
//! never dropped in silence.

use serde::Serialize;

use super::cases::{CaseId, FrameSize, OtherBuild, Path, Phase, Table};
use super::figures::Row;

#[derive(Debug, Clone, Serialize)]
pub struct Ratio {
    pub what: String,
    /// None: a row it needs did not run (`missing` says which).
    pub value: Option<f64>,
    pub aim: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// Which figure of the two rows a ratio divides.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Figure {
    P50,
    P99,
    FramesPerS,
}

impl Figure {
    fn of(self, row: &Row) -> Option<f64> {
        match self {
            Figure::P50 => row.p50_us,
            Figure::P99 => row.p99_us,
            Figure::FramesPerS => row.frames_per_s,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Figure::P50 => "p50",
            Figure::P99 => "p99",
            Figure::FramesPerS => "frames/s",
        }
    }
}

/// One ratio: a figure of row `num` over the same figure of row `den`.
#[derive(Debug, Clone)]
struct RatioDef {
    num: CaseId,
    den: CaseId,
    figure: Figure,
    aim: &'static str,
}

impl RatioDef {
    fn what(&self) -> String {
        let table = match self.num.table {
            Table::Speed => "speed".to_string(),
            Table::Frames { size, phase } => {
                let (w, h) = size.dims();
                match phase {
                    Phase::Throughput => format!("{w}x{h}"),
                    Phase::Latency => format!("{w}x{h} @20 Hz"),
                }
            }
            Table::Contention => "speed under frames".to_string(),
        };
        format!("{table} {}: {} / {}", self.figure.name(), self.num.path.label(), self.den.path.label())
    }
}

/// Every ratio the tables can give, in the order they are reported.
fn definitions(builds: &[OtherBuild]) -> Vec<RatioDef> {
    let mut out = Vec::new();
    speed_ratios(&mut out, builds);
    for size in FrameSize::ALL {
        frame_ratios(&mut out, size);
    }
    let unloaded = CaseId { table: Table::Contention, path: Path::Unloaded };
    for path in [
        Path::Frames30Qos,
        Path::SaturatingQos,
        Path::SaturatingNoQos,
        Path::SaturatingQosKernelBuffers,
        Path::SaturatingQosShm,
        Path::SaturatingQosShmNice,
        Path::SaturatingQosTwoSessions,
    ] {
        let num = CaseId { table: Table::Contention, path };
        out.push(RatioDef { num, den: unloaded.clone(), figure: Figure::P99, aim: "<= 3 (with QoS)" });
    }
    out
}

fn speed_ratios(out: &mut Vec<RatioDef>, builds: &[OtherBuild]) {
    let id = |path: Path| CaseId { table: Table::Speed, path };
    let mut p50 = |num: Path, den: Path, aim: &'static str| {
        out.push(RatioDef { num: id(num), den: id(den), figure: Figure::P50, aim })
    };
    p50(Path::Bus, Path::SeedPythonUdp, "< 1");
    p50(Path::Bus, Path::RawUdp, "<= 2 (moonshot 1.5)");
    p50(Path::BusTwoSessions, Path::SeedPythonUdp, "< 1");
    p50(Path::BusTwoSessions, Path::RawUdp, "<= 2");
    p50(Path::BusTwoSessions, Path::RawZenohLowlatency, "<= 1.1");
    p50(Path::BusTwoSessions, Path::Bus, "-");
    p50(Path::BusTwoSessionsUnix, Path::SeedPythonUdp, "< 1");
    p50(Path::BusTwoSessionsUnix, Path::BusUnix, "-");
    p50(Path::BusTwoSessionsUnix, Path::RawUdp, "<= 2");
    p50(Path::BusUnix, Path::Bus, "-");
    p50(Path::BusUnix, Path::SeedPythonUdp, "< 1");
    p50(Path::BusLowlatencyUnix, Path::SeedPythonUdp, "< 1");
    p50(Path::BusUnix, Path::RawUdp, "<= 2");
    p50(Path::Bus, Path::RawZenoh, "<= 1.1");
    for b in builds {
        let l = &b.label;
        p50(Path::BusBuild(l.clone()), Path::Bus, "-");
        p50(Path::BusUnixBuild(l.clone()), Path::BusUnix, "-");
        p50(Path::BusUnixBuild(l.clone()), Path::SeedPythonUdp, "< 1");
    }
    p50(Path::Bus, Path::RawTcp, "-");
    p50(Path::BusKernelBuffers, Path::Bus, "-");
    p50(Path::BusOneCore, Path::Bus, "-");
    p50(Path::BusOwnRuntime, Path::RawZenohOwnRuntime, "<= 1.1");
    p50(Path::BusOwnRuntime, Path::Bus, "-");
    p50(Path::BusLowlatency, Path::RawUdp, "<= 1.5");
    out.push(RatioDef { num: id(Path::Bus), den: id(Path::RawUdp), figure: Figure::P99, aim: "-" });
}

fn frame_ratios(out: &mut Vec<RatioDef>, size: FrameSize) {
    let through = |path: Path| CaseId { table: Table::Frames { size, phase: Phase::Throughput }, path };
    let latency = |path: Path| CaseId { table: Table::Frames { size, phase: Phase::Latency }, path };
    let fps = Figure::FramesPerS;
    let mut push = |num, den, figure, aim| out.push(RatioDef { num, den, figure, aim });
    push(through(Path::BusShm), through(Path::SeedPythonTcpPickle), fps, ">= 1");
    push(through(Path::BusTcp), through(Path::SeedPythonTcpPickle), fps, ">= 1");
    push(through(Path::BusShm), through(Path::RawTcp), fps, ">= 3");
    push(through(Path::BusTcp), through(Path::RawZenohTcp), fps, ">= 0.9");
    push(through(Path::BusShm), through(Path::RawZenohShm), fps, "-");
    push(latency(Path::BusShmUnix), latency(Path::SeedPythonTcpPickle), Figure::P50, "< 1");
    push(latency(Path::BusTcp), latency(Path::SeedPythonTcpPickle), Figure::P50, "< 1");
    push(latency(Path::BusShmUnixCallback), latency(Path::BusShmUnix), Figure::P50, "-");
    push(latency(Path::BusShmUnixThread), latency(Path::BusShmUnix), Figure::P50, "-");
    push(latency(Path::BusShmUnixThread), latency(Path::BusShmUnixThreadWoken), Figure::P50, "< 1");
}

/// The ratios whose tables ran; a needed row that is absent is named in `missing`.
pub(crate) fn ratios(rows: &[Row], builds: &[OtherBuild]) -> Vec<Ratio> {
    let find = |id: &CaseId| rows.iter().find(|r| &r.id == id);
    let ran = |table: Table| rows.iter().any(|r| r.id.table == table);
    let mut out = Vec::new();
    for def in definitions(builds) {
        if !ran(def.num.table) && !ran(def.den.table) {
            continue;
        }
        let (num, den) = (find(&def.num), find(&def.den));
        let absent: Vec<String> = [(&def.num, num), (&def.den, den)]
            .iter()
            .filter(|(_, r)| r.is_none())
            .map(|(id, _)| id.path.label())
            .collect();
        let value = match (num.and_then(|r| def.figure.of(r)), den.and_then(|r| def.figure.of(r))) {
            (Some(a), Some(b)) if b > 0.0 => Some(a / b),
            _ => None,
        };
        out.push(Ratio {
            what: def.what(),
            value,
            aim: def.aim.into(),
            missing: (!absent.is_empty()).then(|| format!("did not run: {}", absent.join(", "))),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::cases::{cases, other_builds};
    use super::super::Suite;
    use super::*;

    #[test]
    fn every_ratio_names_rows_that_exist() {
        let exe = std::env::current_exe().unwrap();
        let builds = other_builds(&[format!("other={}", exe.display())]).unwrap();
        let all = cases(&[Suite::Speed, Suite::Frames, Suite::Contention], false, &builds, true);
        for def in definitions(&builds) {
            for id in [&def.num, &def.den] {
                assert!(all.iter().any(|c| &c.id == id), "{}: no case {id:?}", def.what());
            }
        }
        let ids: Vec<&CaseId> = all.iter().map(|c| &c.id).collect();
        for (i, id) in ids.iter().enumerate() {
            assert!(!ids[..i].contains(id), "two cases share the id {id:?}");
        }
    }

    fn row(id: CaseId, p50: Option<f64>) -> Row {
        Row {
            suite: id.table.label(),
            path: id.path.label(),
            id,
            runs: 1,
            sent: 1.0,
            received: 1.0,
            lost: 0.0,
            p50_us: p50,
            p99_us: None,
            max_us: None,
            frames_per_s: None,
            mb_per_s: None,
            shared_memory_frames: 0.0,
            background_frames_per_s: None,
            link_p50_us: None,
            handoff_p50_us: None,
        }
    }

    #[test]
    fn a_ratio_is_found_by_id_and_a_missing_row_is_named() {
        let speed = |path| CaseId { table: Table::Speed, path };
        let rows = vec![row(speed(Path::Bus), Some(150.0)), row(speed(Path::SeedPythonUdp), Some(100.0))];
        let out = ratios(&rows, &[]);
        let bus_seed = out.iter().find(|r| r.what == "speed p50: bus / seed: Python UDP").unwrap();
        assert_eq!(bus_seed.value, Some(1.5));
        assert!(bus_seed.missing.is_none());
        let bus_udp = out.iter().find(|r| r.what == "speed p50: bus / raw UDP").unwrap();
        assert_eq!(bus_udp.value, None);
        assert_eq!(bus_udp.missing.as_deref(), Some("did not run: raw UDP"));
        // Tables that did not run give no ratio.
        assert!(out.iter().all(|r| !r.what.starts_with("640x480")));
    }
}
