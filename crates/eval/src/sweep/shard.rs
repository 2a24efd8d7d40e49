//! A sweep across machines: `eval sweep --shard K/N` runs the K-th of N shares of the same
//! sweep (same seed and count: the runs whose index i has i % N == K - 1, so every shard deals
//! every family its share), and `eval sweep-merge` joins the shards' reports into the report
//! one machine would have written: the runs in index order, the rates, the worst runs and the
//! verdict computed again from them. A run is a lockstep run of a seeded scenario, so a merged
//! report's runs and verdicts are the unsharded run's.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SweepReport;
use crate::error::{Error, Result};

/// The K-th (1-based) of N shares of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

impl Shard {
    /// Whether the run at `index` of the whole sweep is this shard's.
    pub fn takes(&self, index: usize) -> bool {
        index % self.n == self.k - 1
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N` with 1 <= K <= N.
    fn from_str(text: &str) -> std::result::Result<Shard, String> {
        let bad = || format!("`{text}` is no shard: give K/N with 1 <= K <= N, e.g. 2/4");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let (k, n) = (k.trim().parse::<usize>().map_err(|_| bad())?, n.trim().parse::<usize>().map_err(|_| bad())?);
        match (1..=n).contains(&k) {
            true => Ok(Shard { k, n }),
            false => Err(bad()),
        }
    }
}

/// `eval sweep-merge`'s command line.
#[derive(Debug, Clone, clap::Args)]
pub struct MergeArgs {
    /// The shards' report directories (or their sweep.json files): every shard of one sweep,
    /// each once
    #[arg(required = true, value_name = "SHARD")]
    pub shards: Vec<PathBuf>,
    /// Where the merged report (sweep.json) and plot (rates.png) go
    #[arg(long = "report", value_name = "DIR", default_value = "reports/sweep")]
    pub out: PathBuf,
    /// The worst runs named in the report
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub worst: usize,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
}

/// A shard's report as its `eval sweep --shard` wrote it.
pub(crate) fn read(path: &Path) -> Result<SweepReport> {
    let file = if path.is_dir() { path.join("sweep.json") } else { path.to_path_buf() };
    let bytes = std::fs::read(&file).map_err(Error::file("read", &file))?;
    serde_json::from_slice(&bytes).map_err(|source| Error::Json { path: file, what: "is no sweep report", source })
}

/// Whether two sweeps ran the same scenarios: seed, --count, --perception and --families.
pub(crate) fn same_scenarios(a: &SweepReport, b: &SweepReport) -> bool {
    a.seed == b.seed && a.count == b.count && a.perception == b.perception && a.asked_families == b.asked_families
}

/// The shards' reports joined into one (see the module doc); refuses shards of different
/// sweeps, a shard twice or a shard missing.
pub fn merge(args: &MergeArgs) -> Result<SweepReport> {
    let reports: Vec<(PathBuf, SweepReport)> =
        args.shards.iter().map(|p| read(p).map(|r| (p.clone(), r))).collect::<Result<_>>()?;
    let (first_path, first) = &reports[0];
    let shard_of = |path: &Path, r: &SweepReport| {
        r.shard.ok_or_else(|| Error::flag(path.display().to_string(), "is the report of a whole sweep, not of a shard"))
    };
    let n = shard_of(first_path, first)?.n;
    let mut seen = vec![false; n];
    for (path, r) in &reports {
        let same = same_scenarios(r, first) && r.own == first.own;
        if !same {
            let rule = format!(
                "is of another sweep than {} (seed, --count, --perception, --families and the nodes under test, --controller and --detector with their files' content, must be the same)",
                first_path.display()
            );
            return Err(Error::flag(path.display().to_string(), rule));
        }
        let s = shard_of(path, r)?;
        if s.n != n || std::mem::replace(&mut seen[s.k - 1], true) {
            return Err(Error::flag(path.display().to_string(), format!("is shard {s}: of another split, or twice")));
        }
    }
    if let Some(k) = seen.iter().position(|s| !s) {
        return Err(Error::flag("SHARD", format!("shard {}/{n} is missing: merge every shard of the sweep", k + 1)));
    }
    let mut runs: Vec<_> = reports.iter().flat_map(|(_, r)| r.runs.iter().cloned()).collect();
    runs.sort_by_key(|r| r.index);
    let wall_s = reports.iter().map(|(_, r)| r.wall_s).fold(0.0, f64::max);
    let jobs = reports.iter().map(|(_, r)| r.jobs).sum();
    let of = super::ReportOf {
        seed: first.seed,
        count: first.count,
        perception: first.perception,
        asked_families: first.asked_families.clone(),
        shard: None,
        own: first.own.clone(),
        out: &args.out,
        worst: args.worst,
    };
    std::fs::create_dir_all(&args.out).map_err(Error::file("create (--report)", &args.out))?;
    Ok(super::report(&of, runs, jobs, wall_s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shard_is_k_of_n_and_the_shards_take_every_index_once() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { k: 2, n: 4 }));
        for bad in ["0/4", "5/4", "2", "a/b", "2/0", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
        let shards: Vec<Shard> = (1..=3).map(|k| Shard { k, n: 3 }).collect();
        for i in 0..100 {
            assert_eq!(shards.iter().filter(|s| s.takes(i)).count(), 1, "index {i}");
        }
    }
}
