//! The library's structure: no module of `src/` reaches itself through its
//! imports, at the top level (`stack`, `formats`, ...) or one level down
//! (`reconstruct::auto`, `reconstruct::method`, ...). A circle means two
//! modules that cannot be read, tested or moved apart; data flows one way
//! (source -> tags -> stack -> reconstruction -> report).
//!
//! The graph is read from the source text: every path from `crate::`,
//! `self::` or `super::` (`super::super::` too, and `{...}` groups
//! expanded), outside comments and `#[cfg(test)]` modules.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a file under `src/` (`src/a/b.rs` and
/// `src/a/b/mod.rs` -> `[a, b]`).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let mut parts: Vec<String> = file
        .strip_prefix(src)
        .unwrap()
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// The paths `code` (of module `me`) names from the crate: every path
/// that starts with `crate::`, `self::` or `super::` (any number of them,
/// each one level up from `me`), resolved to a path from the crate root,
/// with `{...}` groups expanded item by item. A path is the run of
/// lower-case segments (modules, and functions, whose module the cut to a
/// depth keeps); a type or `self` ends it.
fn paths_from_crate(code: &str, me: &[String]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for prefix in ["crate::", "self::", "super::"] {
        for (at, _) in code.match_indices(prefix) {
            // A path's first segment: not the tail of an identifier, and not
            // the second `super` of `super::super::`.
            let before = code[..at].trim_end();
            if before.ends_with("::")
                || code[..at]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c.is_alphanumeric() || c == '_')
            {
                continue;
            }
            let mut base: Vec<String> = match prefix {
                "crate::" => Vec::new(),
                "self::" => me.to_vec(),
                _ => me[..me.len().saturating_sub(1)].to_vec(),
            };
            let mut rest = &code[at + prefix.len()..];
            while let Some(r) = rest.trim_start().strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            expand(rest, base, &mut out);
        }
    }
    out.retain(|p| !p.is_empty());
    out
}

/// The paths `rest` (what follows `base::`) names: a `{...}` group's
/// items, each in turn, or one run of lower-case segments.
fn expand(rest: &str, base: Vec<String>, out: &mut Vec<Vec<String>>) {
    let rest = rest.trim_start();
    if let Some(group) = rest.strip_prefix('{') {
        let (mut depth, mut start) = (0usize, 0usize);
        for (i, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth > 0 => depth -= 1,
                '}' | ',' if depth == 0 => {
                    expand(&group[start..i], base.clone(), out);
                    if c == '}' {
                        return;
                    }
                    start = i + 1;
                }
                _ => {}
            }
        }
        return;
    }
    let mut path = base;
    let mut s = rest;
    loop {
        let ident: String = s
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if ident == "self" || !ident.starts_with(|c: char| c.is_ascii_lowercase()) {
            break;
        }
        s = &s[ident.len()..];
        path.push(ident);
        match s.strip_prefix("::") {
            Some(r) if r.trim_start().starts_with('{') => return expand(r, path, out),
            Some(r) => s = r,
            None => break,
        }
    }
    out.push(path);
}

/// Module -> the modules it imports, each cut to `depth` levels.
fn import_graph(depth: usize) -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let cut = |p: &[String]| p[..p.len().min(depth)].join("::");
    for file in files {
        let module = module_of(&src, &file);
        if module.is_empty() || module[0] == "lib" || module[0] == "bin" {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        let text = text.split("#[cfg(test)]").next().unwrap();
        let code: String = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let me = cut(&module);
        // `super::` in `a/b.rs` and in `a/b/mod.rs` both name `a`'s items.
        let targets = paths_from_crate(&code, &module);
        let entry = graph.entry(me.clone()).or_default();
        for target in targets.iter().filter(|t| !t.is_empty()) {
            let to = cut(target);
            if to != me {
                entry.insert(to);
            }
        }
    }
    graph
}

/// The modules that reach themselves, each with the circle found.
fn circles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    for start in graph.keys() {
        // Depth-first from `start`, remembering the path back.
        let mut stack = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((node, path)) = stack.pop() {
            for next in graph.get(&node).into_iter().flatten() {
                if next == start {
                    found.push(path.clone());
                } else if seen.insert(next.clone()) {
                    let mut longer = path.clone();
                    longer.push(next.clone());
                    stack.push((next.clone(), longer));
                }
            }
        }
    }
    found
}

#[test]
fn no_top_level_module_of_the_library_imports_itself_back() {
    let graph = import_graph(1);
    assert!(graph.len() > 20, "the graph read {} modules", graph.len());
    let found = circles(&graph);
    assert!(found.is_empty(), "module circles: {found:?}");
}

#[test]
fn no_second_level_module_of_the_library_imports_itself_back() {
    let graph = import_graph(2);
    let found = circles(&graph);
    assert!(found.is_empty(), "module circles: {found:?}");
}

#[test]
fn the_circle_finder_finds_a_circle_and_reads_every_kind_of_path() {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    graph.entry("a".into()).or_default().insert("b".into());
    graph.entry("b".into()).or_default().insert("c".into());
    assert!(circles(&graph).is_empty());
    graph.entry("c".into()).or_default().insert("a".into());
    assert_eq!(
        circles(&graph).len(),
        3,
        "each of a, b and c reaches itself"
    );
    let me: Vec<String> = ["acquire", "mock", "emulated"].map(String::from).to_vec();
    let paths = |code: &str| -> Vec<String> {
        let mut p: Vec<String> = paths_from_crate(code, &me)
            .into_iter()
            .map(|p| p.join("::"))
            .collect();
        p.sort();
        p
    };
    assert_eq!(paths("use crate::stack::{Stack}; x_crate::no"), ["stack"]);
    assert_eq!(
        paths("super::method::MethodOptions"),
        ["acquire::mock::method"]
    );
    // Each `super` one level up; `self` is the module itself; groups are
    // expanded, nested ones too.
    assert_eq!(
        paths("use super::super::device::OpenError;"),
        ["acquire::device"]
    );
    assert_eq!(
        paths("use self::conv::{a, B};"),
        [
            "acquire::mock::emulated::conv",
            "acquire::mock::emulated::conv::a"
        ]
    );
    assert_eq!(
        paths("use crate::{files::write_atomic, physics::{kernel, Setup}, Thing};"),
        ["files::write_atomic", "physics", "physics::kernel"]
    );
}

/// What the command line (`src/bin`) must not hold, with what it would be:
/// the library's request ([`scatterscope::acquire::request`]), units
/// ([`scatterscope::units`]) and options hold them, once, for every front
/// end. Each was in `src/bin` before the request moved them (9b42eb9,
/// and ca1cf09 for the last three).
const NOT_IN_THE_COMMAND_LINE: [(&str, &str); 11] = [
    ("/ 100.0", "a length converted between cm and m by hand"),
    ("/ 1000.0", "a time converted between ps and ns by hand"),
    (
        "set a PicoQuant device",
        "the rule of the PicoQuant-only settings",
    ),
    ("whole nanoseconds", "the unit a vendor's library takes"),
    ("whole picoseconds", "the unit a vendor's library takes"),
    (
        "Duration::from_secs(2)",
        "the default duration of an acquisition",
    ),
    (
        "join(\"acquisition.ptu\")",
        "the PTU a vendor's device records by default",
    ),
    ("lbfgs_memory: 7", "a default of admm-lbfgs restated"),
    ("default_value_t = 2e6", "the mock's photon rate restated"),
    (
        "std::env::args()",
        "the command line read again besides the parser",
    ),
    (
        "hide = true, conflicts_with",
        "an old flag name kept by hand",
    ),
];

#[test]
fn the_command_line_holds_no_unit_conversion_device_rule_or_restated_default() {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/bin");
    let mut files = Vec::new();
    rust_files(&bin, &mut files);
    assert!(files.len() > 10, "read {} files", files.len());
    let mut found = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("//") {
                continue;
            }
            for (pattern, what) in NOT_IN_THE_COMMAND_LINE {
                if line.contains(pattern) {
                    found.push(format!(
                        "{}:{}: {what}: {}",
                        file.display(),
                        n + 1,
                        line.trim()
                    ));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "in the command line:\n{}",
        found.join("\n")
    );
}
