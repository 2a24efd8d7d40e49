//! The code's shape, read from its sources (src/ and every crate's under crates/ and
//! examples/): no function runs over 100 lines (test modules included), the binaries only parse
//! and hand over to the library, no two files of one module import each other (directly or
//! round a longer circle), and docs/architecture.md lists every source file. A change that
//! breaks one of these fails here, naming the function, the binary, the circle or the file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest a function may be, its signature and closing brace included.
const MAX_FN_LINES: usize = 100;

/// One source file: the source directory of its crate (`src`, `crates/contract/src`), its path
/// inside it (what `crate::` paths follow), and its text.
struct Source {
    root: String,
    file: PathBuf,
    text: String,
}

impl Source {
    /// The path a person opens: `crates/contract/src/bus/mod.rs`.
    fn shown(&self) -> String {
        format!("{}/{}", self.root, self.file.display())
    }
}

fn sources() -> Vec<Source> {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut roots = vec!["src".to_string()];
    for parent in ["crates", "examples"] {
        let mut crates: Vec<_> = std::fs::read_dir(repo.join(parent)).map_or(Vec::new(), |d| d.flatten().collect());
        crates.sort_by_key(|e| e.file_name());
        roots.extend(crates.iter().map(|c| format!("{parent}/{}/src", c.file_name().to_string_lossy())));
    }
    let mut out = Vec::new();
    for root in roots {
        let src = repo.join(&root);
        let mut files = Vec::new();
        crate::common::rust_files(&src, &mut files);
        files.sort();
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            out.push(Source { root: root.clone(), file: f.strip_prefix(&src).unwrap().to_path_buf(), text });
        }
    }
    out
}

/// The source with comments, string and character literals blanked (newlines kept), so that
/// braces and keywords are counted only where they are code.
fn code_only(text: &str) -> Vec<u8> {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(b.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                let end = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |p| i + p);
                blank(&mut out, i, end);
                i = end;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let (mut depth, mut j) = (1, i + 2);
                while j < b.len() && depth > 0 {
                    if b[j] == b'/' && b.get(j + 1) == Some(&b'*') {
                        depth += 1;
                        j += 1;
                    } else if b[j] == b'*' && b.get(j + 1) == Some(&b'/') {
                        depth -= 1;
                        j += 1;
                    }
                    j += 1;
                }
                blank(&mut out, i, j);
                i = j;
            }
            b'r' if matches!(b.get(i + 1), Some(b'#') | Some(b'"')) && (i == 0 || !is_ident(b[i - 1])) => {
                let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
                if b.get(i + 1 + hashes) != Some(&b'"') {
                    i += 1;
                    continue;
                }
                let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
                let start = i + 2 + hashes;
                let end = b[start..]
                    .windows(close.len())
                    .position(|w| w == close.as_slice())
                    .map_or(b.len(), |p| start + p + close.len());
                blank(&mut out, i, end);
                i = end;
            }
            b'"' => {
                let mut j = i + 1;
                while j < b.len() && b[j] != b'"' {
                    j += if b[j] == b'\\' { 2 } else { 1 };
                }
                blank(&mut out, i, j + 1);
                i = j + 1;
            }
            // A character literal ('x', '\n', '\u{..}'), not a lifetime ('a).
            b'\'' => {
                let end = if b.get(i + 1) == Some(&b'\\') {
                    b[i + 2..].iter().position(|&c| c == b'\'').map(|p| i + 2 + p)
                } else if b.get(i + 2) == Some(&b'\'') {
                    Some(i + 2)
                } else {
                    let ch_len = text[i + 1..].chars().next().map_or(1, char::len_utf8);
                    (b.get(i + 1 + ch_len) == Some(&b'\'')).then_some(i + 1 + ch_len)
                };
                match end {
                    Some(e) => {
                        blank(&mut out, i, e + 1);
                        i = e + 1;
                    }
                    None => i += 1,
                }
            }
            _ => i += 1,
        }
    }
    out
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// The end (one past the closing brace) of the block whose `{` is the first one at or after
/// `from` in `code`; the end of `code` when it never closes.
fn block_end(code: &[u8], from: usize) -> usize {
    let Some(open) = code[from..].iter().position(|&c| c == b'{') else { return code.len() };
    let mut depth = 0i32;
    for (k, &c) in code[from + open..].iter().enumerate() {
        depth += (c == b'{') as i32 - (c == b'}') as i32;
        if depth == 0 {
            return from + open + k + 1;
        }
    }
    code.len()
}

/// `code` with each `#[cfg(test)] mod ... { ... }` blanked (newlines kept): what the library
/// itself is made of, wherever in the file its tests sit.
fn without_test_modules(code: &[u8]) -> Vec<u8> {
    let mut out = code.to_vec();
    let mut i = 0;
    while let Some(p) = out[i..].windows(12).position(|w| w == b"#[cfg(test)]") {
        let at = i + p;
        let rest = String::from_utf8_lossy(&out[at + 12..]).trim_start().to_string();
        let end = if rest.starts_with("mod ") { block_end(&out, at) } else { at + 12 };
        for c in &mut out[at..end] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
        i = end.min(out.len());
    }
    out
}

/// Every function with a body, test modules included: (name, first line, line count).
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let code = code_only(text);
    let line_of = |pos: usize| code[..pos].iter().filter(|&&c| c == b'\n').count() + 1;
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(p) = code[i..].windows(3).position(|w| w == b"fn ") {
        let at = i + p;
        i = at + 3;
        if at > 0 && is_ident(code[at - 1]) {
            continue;
        }
        let name: String = code[at + 3..].iter().take_while(|&&c| is_ident(c)).map(|&c| c as char).collect();
        // The body starts at the first `{` before any `;` (a declaration without a body).
        let Some(open) = code[at..].iter().position(|&c| c == b'{' || c == b';') else { break };
        if code[at + open] == b';' {
            continue;
        }
        // The closing brace: one before the block's end.
        let end = block_end(&code, at + open) - 1;
        let (first, last) = (line_of(at), line_of(end));
        out.push((name, first, last - first + 1));
    }
    out
}

#[test]
fn the_function_finder_counts_code_not_text() {
    let text = "fn a() {\n    let s = \"}\";\n    let c = '{';\n    // }\n    x::<'a>();\n}\n\nfn b();\nfn c(x: u8) -> u8 {\n    x\n}\n";
    assert_eq!(functions(text), vec![("a".to_string(), 1, 6), ("c".to_string(), 9, 3)]);
    // A function after a test module in the middle of a file is still a function.
    let mid = "fn a() {}\n#[cfg(test)]\nmod tests {\n    fn t() {}\n}\nfn b() {\n}\n";
    let names: Vec<String> = functions(mid).into_iter().map(|(n, _, _)| n).collect();
    assert_eq!(names, ["a", "t", "b"]);
    let lib = String::from_utf8(without_test_modules(mid.as_bytes())).unwrap();
    assert!(lib.contains("fn a()") && lib.contains("fn b()") && !lib.contains("fn t()"), "{lib}");
}

#[test]
fn no_function_in_src_runs_over_100_lines() {
    let mut long = Vec::new();
    for source in sources() {
        for (name, line, lines) in functions(&source.text) {
            if lines > MAX_FN_LINES {
                long.push(format!("{}:{line} {name} ({lines} lines)", source.shown()));
            }
        }
    }
    assert!(long.is_empty(), "functions over {MAX_FN_LINES} lines (split them by concern):\n{}", long.join("\n"));
}

/// The most lines a binary's `run` may take: parse, hand over to the library, print.
const MAX_BIN_RUN_LINES: usize = 45;

#[test]
fn binaries_are_thin() {
    let mut fat = Vec::new();
    for source in sources().into_iter().filter(|s| s.file.starts_with("bin")) {
        for (name, line, lines) in functions(&source.text) {
            match name.as_str() {
                "main" => {}
                "run" if lines <= MAX_BIN_RUN_LINES => {}
                "run" => fat.push(format!("{}:{line} run is {lines} lines", source.shown())),
                _ => fat.push(format!("{}:{line} defines {name}", source.shown())),
            }
        }
    }
    assert!(
        fat.is_empty(),
        "a binary is main -> run -> the library (run at most {MAX_BIN_RUN_LINES} lines); move the logic into its \
         tool's command():\n{}",
        fat.join("\n")
    );
}

/// The sibling files a file names: `super::x` and `crate::<its module path>::x`, where x is a
/// file of the same directory.
fn sibling_refs(file: &Path, text: &str, siblings: &BTreeSet<String>) -> BTreeSet<String> {
    let dir: Vec<String> = file
        .parent()
        .into_iter()
        .flat_map(|p| p.components())
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let own = file.file_stem().unwrap().to_string_lossy().into_owned();
    let in_mod = own == "mod";
    let mut prefixes = vec![format!("crate::{}", dir.join("::"))];
    if !in_mod {
        prefixes.push("super".to_string());
    }
    let code = String::from_utf8(without_test_modules(&code_only(text))).unwrap();
    let code = code.as_str();
    let mut refs = BTreeSet::new();
    for prefix in prefixes.iter().filter(|p| p.as_str() != "crate::") {
        let mut rest = code;
        while let Some(i) = rest.find(prefix.as_str()) {
            rest = &rest[i + prefix.len()..];
            let Some(after) = rest.strip_prefix("::") else { continue };
            let names: Vec<String> = match after.strip_prefix('{') {
                Some(group) => group.split('}').next().unwrap_or("").split(',').map(|s| s.trim().to_string()).collect(),
                None => vec![after.to_string()],
            };
            for n in names {
                let name: String = n.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if siblings.contains(&name) && name != own {
                    refs.insert(name);
                }
            }
        }
    }
    refs
}

#[test]
fn no_two_files_of_a_module_import_each_other() {
    let files = sources();
    /// Each directory of a crate (source root, path) and its files (stem, text, path).
    type ByDir<'a> = BTreeMap<(String, PathBuf), Vec<(String, &'a str, &'a Path)>>;
    let mut by_dir: ByDir = BTreeMap::new();
    for s in &files {
        let stem = s.file.file_stem().unwrap().to_string_lossy().into_owned();
        let dir = (s.root.clone(), s.file.parent().unwrap().to_path_buf());
        by_dir.entry(dir).or_default().push((stem, s.text.as_str(), s.file.as_path()));
    }
    let mut circles = Vec::new();
    for ((root, dir), members) in by_dir {
        let names: BTreeSet<String> = members.iter().map(|(n, _, _)| n.clone()).filter(|n| n != "mod").collect();
        let graph: BTreeMap<String, BTreeSet<String>> = members
            .iter()
            .filter(|(n, _, _)| n != "mod")
            .map(|(n, text, file)| (n.clone(), sibling_refs(file, text, &names)))
            .collect();
        // Each circle once, whichever of its files it was found from.
        let mut found: BTreeMap<BTreeSet<String>, Vec<String>> = BTreeMap::new();
        for start in graph.keys() {
            if let Some(path) = circle_through(&graph, start) {
                found.entry(path.iter().cloned().collect()).or_insert(path);
            }
        }
        for path in found.into_values() {
            circles.push(format!("{root}/{}: {}", dir.display(), path.join(" -> ")));
        }
    }
    assert!(
        circles.is_empty(),
        "files that import each other (move what both need into a file of its own):\n{}",
        circles.join("\n")
    );
}

/// A path from `start` back to itself, if the graph has one.
fn circle_through(graph: &BTreeMap<String, BTreeSet<String>>, start: &str) -> Option<Vec<String>> {
    let mut stack = vec![vec![start.to_string()]];
    let mut seen = BTreeSet::new();
    while let Some(path) = stack.pop() {
        let last = path.last().unwrap();
        for next in graph.get(last).into_iter().flatten() {
            if next == start {
                let mut p = path.clone();
                p.push(start.to_string());
                return Some(p);
            }
            if seen.insert(next.clone()) {
                let mut p = path.clone();
                p.push(next.clone());
                stack.push(p);
            }
        }
    }
    None
}

#[test]
fn the_circle_finder_finds_a_circle_and_nothing_in_a_tree() {
    let g = |edges: &[(&str, &str)]| {
        let mut m: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            m.entry(a.to_string()).or_default().insert(b.to_string());
            m.entry(b.to_string()).or_default();
        }
        m
    };
    let circle = g(&[("metrics", "trace"), ("trace", "metrics"), ("judge", "trace")]);
    assert_eq!(circle_through(&circle, "metrics"), Some(vec!["metrics".into(), "trace".into(), "metrics".into()]));
    assert_eq!(circle_through(&circle, "judge"), None, "judge is on no circle");
    let tree = g(&[("judge", "trace"), ("judge", "metrics"), ("metrics", "trace")]);
    assert!(tree.keys().all(|k| circle_through(&tree, k).is_none()));
}

/// The source files a table cell of docs/architecture.md names: comma-separated paths, a bare
/// file name meaning the directory of the path before it, a path ending in `/` a whole directory
/// (returned with its slash). Empty for a cell that is not a list of paths.
fn files_in_cell(cell: &str) -> Vec<String> {
    let items: Vec<&str> = cell.split(", ").map(str::trim).collect();
    let path_like = |i: &str| i.ends_with('/') || i.ends_with(".rs") || i.ends_with(".py");
    if !items.first().is_some_and(|i| i.contains('/')) || !items.iter().all(|i| path_like(i)) {
        return Vec::new();
    }
    let mut dir = String::new();
    let mut out = Vec::new();
    for item in items {
        if let Some(slash) = item.rfind('/') {
            dir = item[..=slash].to_string();
            out.push(item.to_string());
        } else {
            out.push(format!("{dir}{item}"));
        }
    }
    out
}

#[test]
fn the_cell_reader_expands_bare_names_and_skips_prose() {
    assert_eq!(files_in_cell("crates/sim/src/node.rs, args.rs"), ["crates/sim/src/node.rs", "crates/sim/src/args.rs"]);
    assert_eq!(files_in_cell("crates/sim/src/render/"), ["crates/sim/src/render/"]);
    assert!(files_in_cell("the simulated world, src/x.rs").is_empty());
}

#[test]
fn docs_architecture_lists_every_source_file_and_no_other() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(repo.join("docs/architecture.md")).unwrap();
    let listed: Vec<String> = doc
        .lines()
        .filter(|l| l.starts_with('|'))
        .flat_map(|l| l.trim_matches('|').split('|').flat_map(files_in_cell).collect::<Vec<_>>())
        .collect();
    let mut problems = Vec::new();
    let sources = sources();
    for s in &sources {
        let path = s.shown();
        if !listed.iter().any(|l| *l == path || (l.ends_with('/') && path.starts_with(l.as_str()))) {
            problems.push(format!("{path} is in no row of docs/architecture.md's module table"));
        }
    }
    for l in &listed {
        if !repo.join(l).exists() {
            problems.push(format!("docs/architecture.md names {l}, which does not exist"));
        }
    }
    assert!(sources.len() > 100, "only {} sources read", sources.len());
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The names a crate root exports: its `pub mod`s, `pub use`s (the name after `as` where
/// renamed) and items defined there.
fn exported_names(lib_rs: &str) -> Vec<String> {
    let code = String::from_utf8(without_test_modules(&code_only(lib_rs))).unwrap();
    let ident = |s: &str| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>();
    let mut names = Vec::new();
    let mut lines = code.lines();
    while let Some(line) = lines.next() {
        if let Some(rest) = line.strip_prefix("pub use ") {
            let mut stmt = rest.to_string();
            while !stmt.contains(';') {
                stmt.push_str(lines.next().unwrap_or(";"));
            }
            let stmt = stmt.split(';').next().unwrap();
            let list = stmt.rsplit_once("::{").map_or(stmt.rsplit("::").next().unwrap_or(stmt), |(_, l)| l);
            for part in list.trim_end_matches('}').split(',').map(str::trim).filter(|p| !p.is_empty()) {
                let name = part.rsplit(" as ").next().unwrap().rsplit("::").next().unwrap().trim();
                if name != "self" {
                    names.push(name.to_string());
                }
            }
        } else if let Some(item) = ["pub mod ", "pub fn ", "pub struct ", "pub enum ", "pub trait ", "pub const "]
            .iter()
            .find_map(|k| line.strip_prefix(k))
        {
            names.push(ident(item));
        }
    }
    names
}

#[test]
fn the_export_reader_reads_uses_renames_and_items() {
    let lib = "pub mod a;\nmod b;\npub use b::{C, D as E};\npub use f::G;\npub use h as i;\n\
               pub(crate) use j::K;\npub struct L {\n}\npub fn m() {}\n#[cfg(test)]\nmod tests {}\n";
    assert_eq!(exported_names(lib), ["a", "C", "E", "G", "i", "L", "m"]);
}

#[test]
fn docs_architecture_names_what_each_crate_root_exports() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(repo.join("docs/architecture.md")).unwrap();
    let section =
        doc.split("## Public surface").nth(1).expect("a Public surface section").split("\n## ").next().unwrap();
    let mut roots: Vec<(String, std::path::PathBuf)> = std::fs::read_dir(repo.join("crates"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), p.join("src/lib.rs")))
        .collect();
    roots.push(("the root".to_string(), repo.join("src/lib.rs")));
    let mut problems = Vec::new();
    for (name, lib) in &roots {
        let Some(row) = section.lines().find(|l| l.starts_with(&format!("| {name} "))) else {
            problems.push(format!("no row for crate {name}"));
            continue;
        };
        let exported = exported_names(&std::fs::read_to_string(lib).unwrap());
        assert!(exported.len() >= 2, "{name}: only {exported:?} read from {}", lib.display());
        for e in exported.iter().filter(|e| !row.contains(&format!("`{e}`"))) {
            problems.push(format!("{name} exports `{e}`: name it in its row of the Public surface section"));
        }
    }
    assert!(roots.len() >= 8, "{roots:?}");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
