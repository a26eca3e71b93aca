//! The library's structure: no module of `src/` reaches itself through its
//! imports, at the top level (`stack`, `formats`, ...) or one level down
//! (`reconstruct::auto`, `reconstruct::method`, ...). A circle means two
//! modules that cannot be read, tested or moved apart; data flows one way
//! (source -> tags -> stack -> reconstruction -> report).
//!
//! The graph is read from the source text: every `crate::a::b` path and
//! every `super::b`, outside comments and `#[cfg(test)]` modules.

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

/// The identifiers that follow each `prefix` in `code` (`crate::a::b`
/// gives `[a, b]`).
fn paths_after(code: &str, prefix: &str) -> Vec<Vec<String>> {
    code.match_indices(prefix)
        .filter(|(at, _)| {
            // A whole word: not the tail of another identifier.
            !code[..*at]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_alphanumeric() || c == '_')
        })
        .map(|(at, _)| {
            code[at + prefix.len()..]
                .split("::")
                .map(|seg| {
                    seg.chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect::<String>()
                })
                .take_while(|seg| seg.chars().next().is_some_and(|c| c.is_ascii_lowercase()))
                .take(2)
                .collect()
        })
        .filter(|p: &Vec<String>| !p.is_empty())
        .collect()
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
        let parent = &module[..module.len() - 1];
        let mut targets: Vec<Vec<String>> = paths_after(&code, "crate::");
        targets.extend(
            paths_after(&code, "super::")
                .into_iter()
                .map(|p| parent.iter().cloned().chain(p).collect()),
        );
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
fn the_circle_finder_finds_a_circle_and_reads_both_kinds_of_path() {
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
    assert_eq!(
        paths_after("use crate::stack::{Stack}; x_crate::no", "crate::"),
        vec![vec!["stack".to_string()]]
    );
    assert_eq!(
        paths_after("super::method::MethodOptions", "super::"),
        vec![vec!["method".to_string()]]
    );
}
