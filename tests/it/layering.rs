//! The workspace's layering, read from its manifests as cargo sees them (`cargo metadata`):
//! contract <- model <- domain (simulator, perception, ACC) <- orchestration (observe and
//! ros2 <- view and launch <- record <- eval) <- tools (bench, the binaries). The compiler
//! keeps a crate from importing one it does not depend on; this keeps a manifest from adding
//! the dependency that would let it: no edge up the layers and none within one (the ACC never
//! links the simulator, nor the detector; the view never the launcher), so no circle can form.

use std::collections::BTreeMap;

/// Every crate of the workspace and its layer (0 = the contract, the lowest).
const LAYER_OF: &[(&str, u8)] = &[
    ("slipstream-zenoh-contract", 0),
    ("slipstream-zenoh-model", 1),
    ("slipstream-zenoh-sim", 2),
    ("slipstream-zenoh-perception", 2),
    ("slipstream-zenoh-acc", 2),
    // Orchestration, four layers of its own: what observes the bus and the ROS 2 face on the
    // contract; the view and the launcher on them; the recorder on the view (a recording holds
    // the view's copies); the evaluation on everything (it runs, records and reads runs).
    ("slipstream-zenoh-observe", 3),
    ("slipstream-zenoh-ros2", 3),
    ("slipstream-zenoh-view", 4),
    ("slipstream-zenoh-launch", 4),
    ("slipstream-zenoh-record", 5),
    ("slipstream-zenoh-eval", 6),
    ("slipstream-zenoh-bench", 7),
    ("slipstream-zenoh", 8),
    // A user's own nodes: the contract alone (docs/own-node.md).
    ("slipstream-example-own-controller", 8),
    ("slipstream-example-own-detector", 8),
];

fn layer(name: &str) -> Option<u8> {
    LAYER_OF.iter().find(|(n, _)| *n == name).map(|(_, l)| *l)
}

/// Why `from` may not depend on `to` (`dev`: as a dev-dependency), or None when it may.
fn violation(from: &str, to: &str, dev: bool) -> Option<String> {
    let (Some(lf), Some(lt)) = (layer(from), layer(to)) else {
        return Some(format!("`{from}` or `{to}` has no layer: add it to LAYER_OF and docs/architecture.md"));
    };
    if lt > lf {
        return Some(format!("`{from}` (layer {lf}) depends on `{to}` from a higher layer ({lt})"));
    }
    if lf == lt && !dev {
        return Some(format!(
            "`{from}` depends on `{to}` of its own layer ({lf}): crates of one layer share only what is below them"
        ));
    }
    None
}

/// `cargo metadata` of the workspace (its own packages, no dependencies), read once.
fn metadata() -> &'static serde_json::Value {
    static META: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
    META.get_or_init(|| {
        let out = std::process::Command::new(env!("CARGO"))
            .args(["metadata", "--offline", "--no-deps", "--format-version", "1"])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("run cargo metadata");
        assert!(out.status.success(), "cargo metadata: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    })
}

/// Each workspace crate and its dependencies on other workspace crates (name, is-dev), read
/// once for every test here.
fn workspace_edges() -> &'static BTreeMap<String, Vec<(String, bool)>> {
    static EDGES: std::sync::OnceLock<BTreeMap<String, Vec<(String, bool)>>> = std::sync::OnceLock::new();
    EDGES.get_or_init(read_workspace_edges)
}

fn read_workspace_edges() -> BTreeMap<String, Vec<(String, bool)>> {
    let packages = metadata()["packages"].as_array().unwrap();
    let ours: Vec<&str> = packages.iter().filter_map(|p| p["name"].as_str()).collect();
    let mut edges = BTreeMap::new();
    for p in packages {
        let deps = p["dependencies"].as_array().unwrap();
        let inner = deps
            .iter()
            .filter(|d| ours.contains(&d["name"].as_str().unwrap_or("")))
            .map(|d| (d["name"].as_str().unwrap().to_string(), d["kind"].as_str() == Some("dev")))
            .collect();
        edges.insert(p["name"].as_str().unwrap().to_string(), inner);
    }
    edges
}

/// Whether a manifest's text has a `[lints]` table saying `workspace = true`.
fn takes_workspace_lints(manifest: &str) -> bool {
    let table = manifest.split("\n[").find(|t| t.trim_start_matches('[').starts_with("lints]"));
    table.is_some_and(|t| t.lines().skip(1).any(|l| l.replace(' ', "") == "workspace=true"))
}

#[test]
fn every_crate_keeps_the_workspaces_public_surface_lints() {
    let root = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml")).unwrap();
    for lint in ["unreachable_pub", "unnameable_types"] {
        assert!(root.lines().any(|l| l.replace(' ', "") == format!("{lint}=\"deny\"")), "{lint} is not denied");
    }
    let packages = metadata()["packages"].as_array().unwrap();
    assert!(packages.len() >= 14);
    for p in packages {
        let manifest = std::fs::read_to_string(p["manifest_path"].as_str().unwrap()).unwrap();
        assert!(takes_workspace_lints(&manifest), "{} has no `[lints] workspace = true`", p["name"]);
    }
    assert!(!takes_workspace_lints("[package]\nname = \"x\"\n\n[dependencies]\nworkspace = true\n"));
    assert!(takes_workspace_lints("[package]\nname = \"x\"\n\n[lints]\nworkspace = true\n"));
}

#[test]
fn dependencies_point_down_the_layers_and_the_domain_crates_stand_alone() {
    let edges = workspace_edges();
    assert!(edges.len() >= 14, "only {} workspace crates found: {:?}", edges.len(), edges.keys());
    let mut problems = Vec::new();
    for (from, deps) in edges {
        if layer(from).is_none() {
            problems.push(format!("`{from}` has no layer: add it to LAYER_OF and docs/architecture.md"));
        }
        for (to, dev) in deps {
            if let Some(why) = violation(from, to, *dev) {
                problems.push(why);
            }
        }
    }
    assert!(problems.is_empty(), "layering broken:\n{}", problems.join("\n"));
}

#[test]
fn the_acc_and_the_detector_build_without_the_simulator() {
    let edges = workspace_edges();
    for node in ["slipstream-zenoh-acc", "slipstream-zenoh-perception"] {
        let normal: Vec<&str> = edges[node].iter().filter(|(_, dev)| !dev).map(|(n, _)| n.as_str()).collect();
        assert_eq!(normal, ["slipstream-zenoh-contract", "slipstream-zenoh-model"], "{node}");
    }
    let contract = &edges["slipstream-zenoh-contract"];
    assert!(contract.is_empty(), "the contract depends on nothing of ours: {contract:?}");
}

#[test]
fn the_examples_of_a_users_own_nodes_depend_on_the_contract_alone() {
    let edges = workspace_edges();
    let examples: Vec<&String> = edges.keys().filter(|n| n.starts_with("slipstream-example-")).collect();
    assert!(examples.len() >= 2, "{examples:?}");
    for example in examples {
        let ours: Vec<&str> = edges[example].iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(ours, ["slipstream-zenoh-contract"], "{example}");
    }
}

#[test]
fn the_checker_catches_what_it_is_for() {
    assert!(violation("slipstream-zenoh-acc", "slipstream-zenoh-sim", false).is_some());
    assert!(violation("slipstream-zenoh-perception", "slipstream-zenoh-sim", true).is_none());
    assert!(violation("slipstream-zenoh-contract", "slipstream-zenoh-model", true).is_some());
    assert!(violation("slipstream-zenoh-sim", "slipstream-zenoh-launch", false).is_some());
    assert!(violation("slipstream-zenoh-launch", "slipstream-zenoh-sim", false).is_none());
    assert!(violation("slipstream-zenoh-view", "slipstream-zenoh-launch", false).is_some());
    assert!(violation("slipstream-zenoh-view", "slipstream-zenoh-eval", false).is_some());
    assert!(violation("slipstream-zenoh-record", "slipstream-zenoh-view", false).is_none());
    assert!(violation("slipstream-zenoh-new", "slipstream-zenoh-contract", false).is_some());
}
