//! The library's layering (docs/architecture.md §1), checked on its source: every top-level
//! module imports only from layers below its own, and no two library files import each other
//! through a chain of imports.
//!
//! The scan reads every `crate::…`, `super::…` and `self::…` path (use trees included) and, in a
//! `mod.rs` or `lib.rs`, every path through a child module it declares. It resolves a path to the
//! deepest file that it names. Comments, string literals, `#[cfg(test)]` modules and re-exports
//! (`pub use`: a module's façade, not a dependency of its code) are left out.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, bottom first. A module may import from layers strictly below its own.
const LAYERS: &[&[&str]] = &[
    &["atomic_file", "error", "format", "latency", "linalg"],
    &["figure", "ident", "limits", "material", "sparse"],
    &["model"],
    &["integrate"],
    &["excitation", "specimen", "substructure"],
    &["transfer", "lab"],
    &["compensate", "realtime", "site"],
    &["io"],
    &["analysis"],
    &["monitor", "benchmark"],
    &["run"],
    &["output"],
    &["bench", "session", "study"],
];

type Module = Vec<String>;

fn source_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            source_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn module_of(root: &Path, file: &Path) -> Module {
    let rel = file.strip_prefix(root).unwrap().with_extension("");
    let mut parts: Module = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The code without comments, string and char literals.
fn strip(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i = src[i..].find("*/").map_or(b.len(), |j| i + j + 2);
        } else if b[i] == b'r' && (b[i..].starts_with(b"r\"") || b[i..].starts_with(b"r#")) && !ident_byte(b, i) {
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            let close = format!("\"{}", "#".repeat(hashes));
            let start = i + 2 + hashes;
            i = src[start..].find(&close).map_or(b.len(), |j| start + j + close.len());
            out.push_str("\"\"");
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i] == b'\'' && i + 2 < b.len() && (b[i + 1] == b'\\' || b[i + 2] == b'\'') {
            // A char literal (a lifetime has no closing quote right after one character).
            i += if b[i + 1] == b'\\' { 2 } else { 1 };
            while i < b.len() && b[i] != b'\'' {
                i += 1;
            }
            i += 1;
        } else {
            let c = src[i..].chars().next().unwrap();
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

fn ident_byte(b: &[u8], i: usize) -> bool {
    i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_')
}

/// Removes `#[cfg(test)] mod … { … }` blocks and `pub use …;` / `pub(…) use …;` statements.
fn drop_tests_and_reexports(code: &str) -> String {
    let mut s = code.to_string();
    while let Some(at) = s.find("#[cfg(test)]") {
        let rest = &s[at..];
        let Some(open) = rest.find('{') else { break };
        let is_mod = rest[..open].contains("mod ");
        let end = if is_mod {
            let mut depth = 0;
            let mut end = rest.len();
            for (k, c) in rest[open..].char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            end = open + k + 1;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            end
        } else {
            "#[cfg(test)]".len()
        };
        s.replace_range(at..at + end, "");
    }
    let mut out = String::with_capacity(s.len());
    let mut rest = s.as_str();
    while let Some(at) = find_word(rest, "pub") {
        let after = rest[at + 3..].trim_start();
        let after = if after.starts_with('(') {
            after[after.find(')').unwrap() + 1..].trim_start()
        } else {
            after
        };
        if after.starts_with("use ") {
            out.push_str(&rest[..at]);
            let stmt_end = rest[at..].find(';').map_or(rest.len(), |j| at + j + 1);
            rest = &rest[stmt_end..];
        } else {
            out.push_str(&rest[..at + 3]);
            rest = &rest[at + 3..];
        }
    }
    out.push_str(rest);
    out
}

fn find_word(s: &str, word: &str) -> Option<usize> {
    let b = s.as_bytes();
    let mut from = 0;
    while let Some(j) = s[from..].find(word) {
        let at = from + j;
        let end = at + word.len();
        let before_ok = at == 0 || !(b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_' || b[at - 1] == b':');
        let after_ok = end >= b.len() || !(b[end].is_ascii_alphanumeric() || b[end] == b'_');
        if before_ok && after_ok {
            return Some(at);
        }
        from = end;
    }
    None
}

fn ident_at(s: &str) -> Option<&str> {
    let t = s.trim_start();
    let len = t
        .bytes()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == b'_')
        .count();
    (len > 0 && !t.as_bytes()[0].is_ascii_digit()).then(|| &t[..len])
}

/// The full paths of a use tree or path starting at `s` (right after `prefix::`).
fn expand(prefix: &Module, s: &str, out: &mut Vec<Module>) {
    let t = s.trim_start();
    if let Some(inner) = t.strip_prefix('{') {
        let mut depth = 1;
        let mut item = String::new();
        let mut items = Vec::new();
        for c in inner.chars() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                break;
            }
            if depth == 1 && c == ',' {
                items.push(std::mem::take(&mut item));
            } else {
                item.push(c);
            }
        }
        items.push(item);
        for it in items {
            if let Some(name) = ident_at(&it) {
                let rest = it.trim_start()[name.len()..].trim_start();
                let mut p = prefix.clone();
                if name != "self" {
                    p.push(name.to_string());
                }
                match rest.strip_prefix("::") {
                    Some(r) => expand(&p, r, out),
                    None => out.push(p),
                }
            }
        }
        return;
    }
    match ident_at(t) {
        Some(name) => {
            let mut p = prefix.clone();
            p.push(name.to_string());
            let rest = &t[name.len()..];
            match rest.strip_prefix("::") {
                Some(r) => expand(&p, r, out),
                None => out.push(p),
            }
        }
        None => out.push(prefix.clone()),
    }
}

struct Graph {
    files: BTreeMap<Module, PathBuf>,
    edges: BTreeMap<Module, BTreeSet<Module>>,
}

fn resolve(files: &BTreeMap<Module, PathBuf>, path: &Module) -> Option<Module> {
    if path.len() == 1 && matches!(path[0].as_str(), "Error" | "Result") {
        return Some(vec!["error".to_string()]);
    }
    (0..=path.len())
        .rev()
        .map(|k| path[..k].to_vec())
        .find(|p| files.contains_key(p))
}

fn scan() -> Graph {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut paths = Vec::new();
    source_files(&root, &mut paths);
    let files: BTreeMap<Module, PathBuf> = paths.iter().map(|p| (module_of(&root, p), p.clone())).collect();
    let mut edges: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for (module, path) in &files {
        let raw = std::fs::read_to_string(path).unwrap();
        let code = strip(&raw);
        let is_dir_module = path.file_name().is_some_and(|n| n == "mod.rs" || n == "lib.rs");
        let children: BTreeSet<String> = code
            .match_indices("mod ")
            .filter_map(|(at, _)| {
                let rest = &code[at + 4..];
                let name = ident_at(rest)?;
                rest[name.len()..]
                    .trim_start()
                    .starts_with(';')
                    .then(|| name.to_string())
            })
            .collect();
        let code = drop_tests_and_reexports(&code);
        let b = code.as_bytes();
        let mut i = 0;
        while i < b.len() {
            let boundary = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b':');
            let word = boundary
                .then(|| ident_at(&code[i..]))
                .flatten()
                .filter(|_| !b[i].is_ascii_whitespace());
            let Some(word) = word else {
                i += 1;
                continue;
            };
            let after = i + word.len();
            if !code[after..].starts_with("::") {
                i = after;
                continue;
            }
            let mut base: Option<Module> = match word {
                "crate" => Some(Vec::new()),
                "self" => Some(module.clone()),
                "super" => Some(module[..module.len().saturating_sub(1)].to_vec()),
                child if is_dir_module && children.contains(child) => {
                    let mut m = module.clone();
                    m.push(child.to_string());
                    Some(m)
                }
                _ => None,
            };
            let mut pos = after + 2;
            if let Some(ref mut m) = base {
                if word == "crate" || word == "super" || word == "self" {
                    while code[pos..].starts_with("super::") {
                        m.pop();
                        pos += "super::".len();
                    }
                }
                let mut found = Vec::new();
                expand(m, &code[pos..], &mut found);
                for p in found {
                    if let Some(target) = resolve(&files, &p)
                        && &target != module
                        && !target.is_empty()
                    {
                        edges.entry(module.clone()).or_default().insert(target);
                    }
                }
            }
            i = pos;
        }
    }
    Graph { files, edges }
}

/// Strongly connected components with more than one member (Tarjan).
fn cycles(nodes: &[Module], edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct State<'a> {
        edges: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<Module, usize>,
        low: BTreeMap<Module, usize>,
        stack: Vec<Module>,
        on_stack: BTreeSet<Module>,
        found: Vec<Vec<Module>>,
    }
    fn visit(v: &Module, st: &mut State) {
        let n = st.index.len();
        st.index.insert(v.clone(), n);
        st.low.insert(v.clone(), n);
        st.stack.push(v.clone());
        st.on_stack.insert(v.clone());
        for w in st.edges.get(v).into_iter().flatten() {
            if !st.index.contains_key(w) {
                visit(w, st);
                let lw = st.low[w];
                let lv = st.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if st.on_stack.contains(w) {
                let iw = st.index[w];
                let lv = st.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if st.low[v] == st.index[v] {
            let mut component = Vec::new();
            loop {
                let w = st.stack.pop().unwrap();
                st.on_stack.remove(&w);
                let done = &w == v;
                component.push(w);
                if done {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                st.found.push(component);
            }
        }
    }
    let mut st = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in nodes {
        if !st.index.contains_key(v) {
            visit(v, &mut st);
        }
    }
    st.found
}

fn name(m: &Module) -> String {
    if m.is_empty() { "lib".into() } else { m.join("/") }
}

#[test]
fn the_scan_sees_the_imports_it_checks() {
    let g = scan();
    let has = |a: &str, b: &str| {
        let a: Module = a.split('/').map(String::from).collect();
        let b: Module = b.split('/').map(String::from).collect();
        g.edges.get(&a).is_some_and(|t| t.contains(&b))
    };
    // `use super::record::{Record, …}`, `crate::integrate::FohMap`, `use crate::error::…`.
    assert!(has("excitation/readers", "excitation/record"));
    assert!(has("excitation/spectrum", "integrate"));
    assert!(has("model/sparse_modes", "sparse"));
    // A parent's path through a child it declares (`mat5::write_file` in io/results/mod.rs).
    assert!(has("io/results", "io/results/mat5"));
    // The shared leaves that keep parents and children of io/config and site/server apart.
    assert!(has("io/config/structure", "io/config/common"));
    assert!(has("site/server/tcp", "site/server/options"));
    assert!(has("site/server/tcp", "site/server/session"));
    let total: usize = g.edges.values().map(BTreeSet::len).sum();
    assert!(
        g.files.len() > 100 && total > 400,
        "{} files, {total} edges",
        g.files.len()
    );
}

#[test]
fn the_cycle_finder_finds_a_planted_cycle() {
    let m = |s: &str| vec![s.to_string()];
    let nodes = vec![m("a"), m("b"), m("c"), m("d")];
    let mut edges: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    edges.entry(m("a")).or_default().insert(m("b"));
    edges.entry(m("b")).or_default().insert(m("c"));
    edges.entry(m("c")).or_default().insert(m("a"));
    edges.entry(m("d")).or_default().insert(m("a"));
    assert_eq!(cycles(&nodes, &edges), vec![vec![m("a"), m("b"), m("c")]]);
    edges.get_mut(&m("c")).unwrap().clear();
    assert!(cycles(&nodes, &edges).is_empty());
}

#[test]
fn every_module_imports_only_from_layers_below_it() {
    let g = scan();
    let rank = |m: &str| LAYERS.iter().position(|layer| layer.contains(&m));
    let tops: BTreeSet<&str> = g.files.keys().filter_map(|m| m.first().map(String::as_str)).collect();
    let unplaced: Vec<_> = tops.iter().filter(|m| rank(m).is_none()).collect();
    assert!(
        unplaced.is_empty(),
        "modules missing from LAYERS (and docs/architecture.md §1): {unplaced:?}"
    );
    let mut upward = Vec::new();
    for (from, targets) in &g.edges {
        let Some(a) = from.first() else { continue };
        for to in targets {
            let b = &to[0];
            if a != b && rank(b) >= rank(a) {
                upward.push(format!("{} -> {}", name(from), name(to)));
            }
        }
    }
    assert!(
        upward.is_empty(),
        "imports from the same or a higher layer:\n{}",
        upward.join("\n")
    );
}

#[test]
fn no_two_library_files_import_each_other() {
    let g = scan();
    let nodes: Vec<Module> = g.files.keys().cloned().collect();
    let found: Vec<String> = cycles(&nodes, &g.edges)
        .iter()
        .map(|c| c.iter().map(name).collect::<Vec<_>>().join(" ↔ "))
        .collect();
    assert!(found.is_empty(), "import circles between files:\n{}", found.join("\n"));
}

/// The front ends stay thin (issue 41): everything a command produces is made by the library,
/// so the `substep` binary is argument parsing, calls and printing — at most 3000 lines — and
/// the stepping engine is not in `io`.
#[test]
fn the_command_line_front_end_stays_thin() {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR")).join("../substep-cli/src");
    let mut files = Vec::new();
    source_files(&cli, &mut files);
    let lines: usize = files
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap().lines().count())
        .sum();
    assert!(files.len() > 10, "{} files under {}", files.len(), cli.display());
    assert!(
        lines <= 3000,
        "crates/substep-cli/src has {lines} lines (limit 3000): move what it produces into the library"
    );
    let lib = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    assert!(
        !lib.join("io/run.rs").exists() && !lib.join("io/run").exists(),
        "the run loop belongs in run/, not io/"
    );
}
