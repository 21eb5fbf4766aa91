//! The layering rule of docs/ARCHITECTURE.md, read from the source: every `crate::` path in a
//! module under src/ must point to a module of a strictly lower layer (or its own), and the
//! graph of submodules (`crate::a::b`, `super::`) must have no cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The declared layers, lowest first. A module may use only modules of lower layers; two
/// modules of one layer may not use each other.
const LAYERS: &[&[&str]] = &[
    &["units", "geom"],
    &["model"],
    &["law"],
    &["cam", "estimate"],
    &["design"],
    &["part"],
    &["toolpath"],
    &["outputs", "sweep", "verdict"],
    &["render"],
    &["export"],
    &["spec"],
    &["error"],
    &["app"],
    &["bin"],
];

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

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

/// The module path of a source file: `src/cam/checks.rs` -> ["cam", "checks"],
/// `src/part/mod.rs` -> ["part"], `src/bin/...` -> ["bin"].
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts[0] == "bin" {
        return vec!["bin".into()];
    }
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// The code of a file without comments and string contents (good enough for paths).
fn code_lines(text: &str) -> Vec<String> {
    text.lines()
        .map(|l| {
            let l = l.trim_start();
            if l.starts_with("//") {
                return String::new();
            }
            let mut out = String::new();
            let mut in_str = false;
            let mut prev = ' ';
            for c in l.chars() {
                if c == '"' && prev != '\\' {
                    in_str = !in_str;
                } else if !in_str {
                    out.push(c);
                }
                prev = c;
            }
            out
        })
        .collect()
}

/// Every path that starts with `root::` in the code, as its segments.
fn paths_after(code: &str, root: &str) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    let pat = format!("{root}::");
    let mut rest = code;
    while let Some(i) = rest.find(&pat) {
        let before = rest[..i].chars().last();
        rest = &rest[i + pat.len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        // Segments up to the first one that does not end at `::`.
        let mut segs: Vec<String> = Vec::new();
        for s in rest.split("::") {
            let ident: String = s
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if ident.is_empty() {
                break;
            }
            let whole = ident.len() == s.len();
            segs.push(ident);
            if !whole {
                break;
            }
        }
        // `crate::{a, b}`: each group member is a path of its own.
        if segs.is_empty() && rest.starts_with('{') {
            let end = rest.find('}').unwrap_or(rest.len());
            for item in rest[1..end].split(',') {
                let first: String = item
                    .trim()
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !first.is_empty() {
                    found.push(vec![first]);
                }
            }
        } else if !segs.is_empty() {
            found.push(segs);
        }
    }
    found
}

struct Graph {
    /// Top-level module -> (used top-level module -> first place it is used).
    top: BTreeMap<String, BTreeMap<String, String>>,
    /// Submodule -> submodules it uses.
    sub: BTreeMap<String, BTreeSet<String>>,
}

fn graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let tops: BTreeSet<String> = files
        .iter()
        .filter_map(|f| module_of(&src, f).first().cloned())
        .collect();
    let mut g = Graph {
        top: BTreeMap::new(),
        sub: BTreeMap::new(),
    };
    for file in &files {
        let module = module_of(&src, file);
        if module.is_empty() {
            continue; // lib.rs: declarations and re-exports only
        }
        let text = std::fs::read_to_string(file).unwrap();
        let code = code_lines(&text).join("\n");
        let root = if module[0] == "bin" {
            "camspring"
        } else {
            "crate"
        };
        let me = module.join("::");
        for path in paths_after(&code, root) {
            if !tops.contains(&path[0]) {
                continue; // a re-exported item of lib.rs
            }
            if path[0] != module[0] {
                g.top
                    .entry(module[0].clone())
                    .or_default()
                    .entry(path[0].clone())
                    .or_insert_with(|| file.display().to_string());
            }
            let target = match path.get(1) {
                Some(s) if src.join(&path[0]).join(format!("{s}.rs")).exists() => {
                    format!("{}::{s}", path[0])
                }
                _ => path[0].clone(),
            };
            if target != me {
                g.sub.entry(me.clone()).or_default().insert(target);
            }
        }
        if module.len() > 1 {
            for _ in paths_after(&code, "super") {
                let parent = module[..module.len() - 1].join("::");
                g.sub.entry(me.clone()).or_default().insert(parent);
            }
        }
    }
    g
}

#[test]
fn every_module_is_in_a_declared_layer() {
    let g = graph();
    for (module, uses) in &g.top {
        assert!(layer(module).is_some(), "src/{module} is in no layer");
        for used in uses.keys() {
            assert!(layer(used).is_some(), "src/{used} is in no layer");
        }
    }
}

#[test]
fn imports_only_run_down_the_layers() {
    let g = graph();
    let mut wrong = Vec::new();
    for (module, uses) in &g.top {
        let (Some(lm), _) = (layer(module), ()) else {
            continue;
        };
        for (used, at) in uses {
            if layer(used).is_some_and(|lu| lu >= lm) {
                wrong.push(format!("{module} uses {used} (first in {at})"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "imports against the layer order:\n  {}",
        wrong.join("\n  ")
    );
    // The rule has teeth: the graph really holds the downward edges it checks.
    assert!(g.top["app"].contains_key("design"));
    assert!(g.top["design"].contains_key("cam"));
    assert!(g.top["cam"].contains_key("model"));
}

#[test]
fn the_submodule_graph_has_no_cycle() {
    let g = graph();
    // Depth-first search with colours: grey on the stack, black done.
    fn visit(
        n: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        colour: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        colour.insert(n.to_string(), 1);
        stack.push(n.to_string());
        for m in g.get(n).into_iter().flatten() {
            match colour.get(m.as_str()).copied().unwrap_or(0) {
                1 => {
                    let i = stack.iter().position(|s| s == m).unwrap();
                    let mut cycle = stack[i..].to_vec();
                    cycle.push(m.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(m, g, colour, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        colour.insert(n.to_string(), 2);
        None
    }
    let mut colour = BTreeMap::new();
    for n in g.sub.keys() {
        if colour.get(n.as_str()).copied().unwrap_or(0) == 0 {
            let cycle = visit(n, &g.sub, &mut colour, &mut Vec::new());
            assert!(
                cycle.is_none(),
                "import cycle: {}",
                cycle.unwrap().join(" -> ")
            );
        }
    }
    assert!(g.sub.len() > 20, "too few modules seen: {:?}", g.sub.keys());
}

#[test]
fn the_reader_sees_grouped_and_nested_paths() {
    let code = "use crate::{model::Spec, law};\nlet x = crate::cam::checks::run();\nmycrate::no";
    let paths = paths_after(code, "crate");
    assert_eq!(paths[0], vec!["model".to_string()]);
    assert_eq!(paths[1], vec!["law".to_string()]);
    assert_eq!(paths[2], vec!["cam", "checks", "run"]);
    assert_eq!(paths.len(), 3);
    assert_eq!(code_lines("// crate::x\n\"crate::y\" z")[1], " z");
}
