//! The library's layering, read from its sources: contract <- domain <- orchestration <- tools
//! (src/lib.rs). A module imports from its own layer or lower ones; the domain modules stand
//! alone on the contract, the shared vehicle model and the road geometry (the ACC never links
//! the simulator, nor the detector). A new import that breaks this fails here, naming the file and line.

use std::path::Path;

/// Every top-level module and its layer (0 = contract, the lowest).
const LAYER_OF: &[(&str, u8)] = &[
    ("msg", 0),
    ("topics", 0),
    ("qos", 0),
    ("config", 0),
    ("bus", 0),
    ("vehicle", 1),
    ("road", 1),
    ("sim", 1),
    ("perception", 1),
    ("acc", 1),
    ("launch", 2),
    ("record", 2),
    ("view", 2),
    ("ros2", 2),
    ("eval", 2),
    ("tools", 3),
    ("bench", 3),
    ("cli", 3),
];

/// Within the domain layer, the only imports across modules: the shared vehicle model and road
/// geometry.
const DOMAIN_SHARED: &[&str] = &["vehicle", "road"];

/// Within orchestration: recordings may hold the view's Foxglove copies and ROS 2 messages,
/// evaluation runs the loop through launch and reads recordings; never the other way.
const ORCHESTRATION_ORDER: &[&str] = &["launch", "view", "ros2", "record", "eval"];

/// Names the crate root re-exports from the contract (`crate::Bus`, ...).
const ROOT_REEXPORTS: &[(&str, &str)] =
    &[("Bus", "bus"), ("BusError", "bus"), ("ConnectArgs", "config"), ("TopicMap", "config")];

fn layer(module: &str) -> Option<u8> {
    LAYER_OF.iter().find(|(m, _)| *m == module).map(|(_, l)| *l)
}

/// The top-level module a file under src/ belongs to (None: lib.rs and the binaries).
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    match first.as_str() {
        "lib.rs" | "bin" => None,
        f => Some(f.trim_end_matches(".rs").to_string()),
    }
}

/// The modules a line names through `crate::` (paths and `use crate::{a, b::c}` groups).
fn crate_refs(line: &str) -> Vec<String> {
    let mut refs = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let inner = group.split('}').next().unwrap_or("");
            for item in inner.split(',') {
                let name: String = item.trim().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if !name.is_empty() {
                    refs.push(name);
                }
            }
        } else {
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            refs.push(name);
        }
    }
    refs.into_iter().map(|r| ROOT_REEXPORTS.iter().find(|(n, _)| *n == r).map_or(r, |(_, m)| m.to_string())).collect()
}

/// Why `from` may not import `to`, or None when it may.
fn violation(from: &str, to: &str) -> Option<String> {
    if from == to {
        return None;
    }
    let (Some(lf), Some(lt)) = (layer(from), layer(to)) else {
        return Some(format!("`{to}` or `{from}` has no layer: add it to LAYER_OF (and to src/lib.rs's overview)"));
    };
    if lt > lf {
        return Some(format!("`{from}` (layer {lf}) imports `{to}` from a higher layer ({lt})"));
    }
    if lf == 1 && lt == 1 && !DOMAIN_SHARED.contains(&to) {
        return Some(format!(
            "domain module `{from}` imports domain module `{to}`: only {} are shared",
            DOMAIN_SHARED.join(" and ")
        ));
    }
    if lf == 2 && lt == 2 {
        let pos = |m: &str| ORCHESTRATION_ORDER.iter().position(|x| *x == m);
        if pos(to) > pos(from) {
            return Some(format!("`{from}` imports `{to}`: orchestration goes {ORCHESTRATION_ORDER:?}"));
        }
    }
    None
}

#[test]
fn imports_point_down_the_layers_and_the_domain_modules_stand_alone() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    crate::common::rust_files(&src, &mut files);
    files.sort();
    let mut problems = Vec::new();
    let mut checked = 0;
    for file in &files {
        let Some(from) = module_of(&src, file) else { continue };
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("//") {
                continue;
            }
            for to in crate_refs(line) {
                checked += 1;
                if let Some(why) = violation(&from, &to) {
                    problems.push(format!("{}:{}: {why}\n    {}", file.display(), n + 1, line.trim()));
                }
            }
        }
    }
    assert!(checked > 100, "only {checked} imports found: is the scan still reading src/?");
    assert!(problems.is_empty(), "layering broken:\n{}", problems.join("\n"));
}

#[test]
fn the_checker_catches_what_it_is_for() {
    assert!(violation("acc", "sim").is_some(), "the ACC must not link the simulator");
    assert!(violation("perception", "sim").is_some());
    assert!(violation("sim", "eval").is_some());
    assert!(violation("bus", "tools").is_some());
    assert!(violation("launch", "eval").is_some());
    assert!(violation("acc", "vehicle").is_none());
    assert!(violation("eval", "launch").is_none());
    assert!(violation("tools", "msg").is_none());
    assert!(violation("newthing", "msg").is_some(), "a module without a layer is named");
    assert_eq!(crate_refs("use crate::{topics, Bus};"), ["topics", "bus"]);
    assert_eq!(crate_refs("let x = crate::sim::rng::SimRng::new(1); crate::acc::X"), ["sim", "acc"]);
}

#[test]
fn every_module_of_the_library_has_a_layer() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    for line in lib.lines() {
        if let Some(m) = line.strip_prefix("pub mod ").and_then(|r| r.strip_suffix(';')) {
            assert!(layer(m).is_some(), "src/lib.rs declares `{m}` but LAYER_OF gives it no layer");
        }
    }
}
