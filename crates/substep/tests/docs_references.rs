//! References in the repository stay inside it (issue 12): no text file points to the external
//! reference material or its specification sections, every `docs/theory.md §N.M` names a
//! section that exists, and every relative Markdown link in `docs/*.md` and `README.md` leads
//! to a file (and, with a `#fragment`, to an anchor) that exists. A second test plants each kind
//! of bad reference in memory and checks the scanner reports it with its file:line, so the
//! repository check cannot pass by finding nothing.

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// Built with `concat!` so this file does not contain the strings it forbids.
const FORBIDDEN: [&str; 4] = [
    concat!("shared", "/spec"),
    concat!("shared", "/data"),
    concat!("shared", "/research"),
    concat!("spec ", "§"),
];

/// Build output, the git store and the CLI's default output folder (ignored by git).
const SKIP_DIRS: [&str; 3] = ["target", ".git", "results"];

/// Larger files are data, not text anyone cites from; skipping them bounds the read.
const MAX_TEXT_BYTES: u64 = 16 << 20;

const THEORY: &str = "docs/theory.md";

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every text file under `root` as (path relative to `root` with `/` separators, contents), in
/// sorted order. Binary files (a NUL byte or not UTF-8) and symlinks (no cycles) are skipped.
fn text_files(root: &Path) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let mut entries: Vec<_> = fs::read_dir(root.join(&rel))
            .unwrap_or_else(|e| panic!("{}: cannot list: {e}", rel.display()))
            .map(|e| e.expect("directory entry"))
            .collect();
        entries.sort_by_key(|e| e.file_name());
        for e in entries {
            let name = e.file_name().to_string_lossy().into_owned();
            let meta = e.path().symlink_metadata().expect("metadata");
            let child = rel.join(&name);
            if meta.is_dir() {
                if !SKIP_DIRS.contains(&name.as_str()) {
                    stack.push(child);
                }
            } else if meta.is_file() && meta.len() <= MAX_TEXT_BYTES {
                let bytes = fs::read(e.path()).expect("read file");
                if bytes.contains(&0) {
                    continue;
                }
                if let Ok(text) = String::from_utf8(bytes) {
                    let rel = child
                        .components()
                        .map(|c| c.as_os_str().to_string_lossy())
                        .collect::<Vec<_>>();
                    out.push((rel.join("/"), text));
                }
            }
        }
    }
    out.sort();
    out
}

/// The section numbers `N` / `N.M` of the anchors `id="sN.M"` in a Markdown text.
fn section_anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices("id=\"s") {
        let rest = &text[i + 5..];
        if let Some(end) = rest.find('"')
            && let Some((sec, n)) = parse_section(&rest[..end])
            && n == end
        {
            out.insert(sec);
        }
    }
    out
}

/// A section number `N` or `N.M` at the start of `s`, and the bytes it takes. A trailing `.`
/// without a digit after it ends a sentence, not the number.
fn parse_section(s: &str) -> Option<(String, usize)> {
    let b = s.as_bytes();
    let digits = |from: usize| b[from..].iter().take_while(|c| c.is_ascii_digit()).count();
    let major = digits(0);
    if major == 0 {
        return None;
    }
    let mut n = major;
    if b.get(n) == Some(&b'.') {
        let minor = digits(n + 1);
        if minor > 0 {
            n += 1 + minor;
        }
    }
    Some((s[..n].to_string(), n))
}

/// `§N` / `§N.M` at the start of `s`, followed by any chained `, §X`, ` and §X`, `–§X`.
fn section_chain(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = s;
    while let Some(after) = rest.strip_prefix('§') {
        let Some((sec, n)) = parse_section(after) else { break };
        out.push(sec);
        rest = &after[n..];
        match [", ", "; ", " and ", ", and ", "–", "-"]
            .iter()
            .find_map(|sep| rest.strip_prefix(sep))
        {
            Some(r) if r.starts_with('§') => rest = r,
            _ => break,
        }
    }
    out
}

/// The theory sections a line cites: `theory.md §N.M` (also `` `theory.md` §N `` and
/// `[theory.md](theory.md) §N`, with chains `§A, §B`), `theory.md#sN.M`, and, inside
/// docs/theory.md itself, every bare `§N.M`.
fn theory_refs(line: &str, in_theory: bool) -> Vec<String> {
    let mut out = Vec::new();
    if in_theory {
        for (i, _) in line.match_indices('§') {
            out.extend(section_chain(&line[i..]).into_iter().take(1));
        }
        return out;
    }
    for (i, _) in line.match_indices("theory.md") {
        let mut rest = &line[i + "theory.md".len()..];
        if let Some(frag) = rest.strip_prefix("#s") {
            if let Some((sec, _)) = parse_section(frag) {
                out.push(sec);
            }
            continue;
        }
        rest = rest.strip_prefix(['`', ')']).unwrap_or(rest);
        out.extend(section_chain(rest.trim_start_matches(' ')));
    }
    out
}

/// `a`..`z`, digits, `-`, `_` kept, spaces to `-`, the rest dropped: GitHub's heading anchors.
fn heading_slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

/// Explicit `id="…"` anchors and heading slugs of a Markdown text.
fn markdown_anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices("id=\"") {
        if let Some(end) = text[i + 4..].find('"') {
            out.insert(text[i + 4..i + 4 + end].to_string());
        }
    }
    for line in text.lines() {
        let hashes = line.bytes().take_while(|&c| c == b'#').count();
        if hashes > 0 && line[hashes..].starts_with(' ') {
            out.insert(heading_slug(&line[hashes..]));
        }
    }
    out
}

/// Relative link targets `](target)` of one Markdown line (no URLs, no mail addresses).
fn markdown_links(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    for (i, _) in line.match_indices("](") {
        let rest = &line[i + 2..];
        let Some(end) = rest.find(')') else { continue };
        let target = rest[..end].split_whitespace().next().unwrap_or("");
        if !(target.is_empty() || target.contains("://") || target.starts_with("mailto:")) {
            out.push(target);
        }
    }
    out
}

fn is_linked_markdown(path: &str) -> bool {
    path == "README.md" || (path.starts_with("docs/") && !path[5..].contains('/') && path.ends_with(".md"))
}

/// Resolves `target` relative to the folder of `from` (both `/`-separated, repository-relative);
/// `None` if it climbs out of the repository.
fn resolve(from: &str, target: &str) -> Option<String> {
    let mut parts: Vec<&str> = from.split('/').collect();
    parts.pop();
    for p in target.split('/') {
        match p {
            "" | "." => {}
            ".." => {
                parts.pop()?;
            }
            p => parts.push(p),
        }
    }
    Some(parts.join("/"))
}

/// Every problem in `files` as `file:line: reason`. `exists` says whether a repository-relative
/// path is a file or folder; `read` gives a Markdown file's text for its anchors.
fn problems(
    files: &[(String, String)],
    exists: &dyn Fn(&str) -> bool,
    read: &dyn Fn(&str) -> Option<String>,
) -> Vec<String> {
    let mut out = Vec::new();
    let theory = files.iter().find(|(p, _)| p == THEORY).map(|(_, t)| t.as_str());
    let Some(theory) = theory else {
        return vec![format!("{THEORY}: missing")];
    };
    let sections = section_anchors(theory);
    for (path, text) in files {
        let markdown = is_linked_markdown(path);
        let mut fenced = false;
        for (n, line) in text.lines().enumerate() {
            let at = format!("{path}:{}", n + 1);
            let lower = line.to_lowercase();
            for pat in FORBIDDEN {
                for (i, _) in lower.match_indices(pat) {
                    let word_start = !lower[..i].chars().next_back().is_some_and(|c| c.is_alphanumeric());
                    if !pat.starts_with("spec") || word_start {
                        out.push(format!(
                            "{at}: refers to `{pat}` outside the repository (cite {THEORY})"
                        ));
                    }
                }
            }
            for sec in theory_refs(line, path == THEORY) {
                if !sections.contains(&sec) {
                    out.push(format!("{at}: §{sec} has no anchor id=\"s{sec}\" in {THEORY}"));
                }
            }
            if markdown {
                if line.trim_start().starts_with("```") {
                    fenced = !fenced;
                }
                if fenced {
                    continue;
                }
                for target in markdown_links(line) {
                    let (file, frag) = target.split_once('#').unwrap_or((target, ""));
                    let file = if file.is_empty() {
                        Some(path.clone())
                    } else {
                        resolve(path, file)
                    };
                    let Some(file) = file.filter(|f| exists(f)) else {
                        out.push(format!("{at}: link `{target}`: no such file"));
                        continue;
                    };
                    if !frag.is_empty() && file.ends_with(".md") {
                        let anchors = read(&file).map(|t| markdown_anchors(&t)).unwrap_or_default();
                        if !anchors.contains(frag) {
                            out.push(format!("{at}: link `{target}`: no anchor `{frag}` in {file}"));
                        }
                    }
                }
            }
        }
    }
    out
}

#[test]
fn repository_references_stay_inside_and_resolve() {
    let root = repo_root();
    let files = text_files(&root);
    // Guards against walking the wrong folder and passing on nothing.
    let names: BTreeSet<&str> = files.iter().map(|(p, _)| p.as_str()).collect();
    for must in [THEORY, "README.md", "crates/substep/src/lib.rs", "docs/architecture.md"] {
        assert!(names.contains(must), "{must} not found under {}", root.display());
    }
    let cited: usize = files
        .iter()
        .map(|(p, t)| t.lines().map(|l| theory_refs(l, p == THEORY).len()).sum::<usize>())
        .sum();
    assert!(
        cited > 100,
        "only {cited} theory references found: is the scanner broken?"
    );
    let anchors = section_anchors(
        files
            .iter()
            .find(|(p, _)| p == THEORY)
            .map(|(_, t)| t.as_str())
            .unwrap(),
    );
    assert!(
        anchors.contains("3.4") && anchors.contains("13"),
        "theory anchors: {anchors:?}"
    );

    let exists = |p: &str| root.join(p).exists();
    let read = |p: &str| fs::read_to_string(root.join(p)).ok();
    let found = problems(&files, &exists, &read);
    assert!(
        found.is_empty(),
        "{} bad reference(s):\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn scanner_reports_each_kind_of_bad_reference_with_its_line() {
    // The missing sections go in as format arguments, so the repository check of this very
    // file does not see them.
    let (s21, s4, s7, s99) = ("2.1", "4", "7", "9.9");
    let theory = "# T\n<a id=\"s1\"></a>\n## 1\n<a id=\"s1.2\"></a>\n### 1.2 Sign\nSee §1.2 and §1.3.\n";
    let lib = format!(
        "//! ok: docs/theory.md §1.2, §1\n//! bad: docs/theory.md §1.2, §{s21}\n//! see {}/notes.md\n\
         //! the {} 3 step\n//! `theory.md` §{s7} and theory.md#s1.2 and theory.md#s{s99}.\n",
        FORBIDDEN[0], FORBIDDEN[3]
    );
    let readme = format!(
        "# R\n[theory](docs/theory.md#s1.2) [gone](docs/nothing.md) [frag](docs/theory.md#s{s4})\n\
         [self](#r) [web](https://example.org/x) [up](../outside)\n```\n[code](not/checked)\n```\n"
    );
    let files: Vec<(String, String)> = vec![
        ("README.md".into(), readme),
        ("crates/x/src/lib.rs".into(), lib),
        (THEORY.into(), theory.into()),
    ];
    let exists = |p: &str| files.iter().any(|(f, _)| f == p);
    let read = |p: &str| files.iter().find(|(f, _)| f == p).map(|(_, t)| t.clone());
    let found = problems(&files, &exists, &read);
    let expected = [
        format!("README.md:2: §{s4} has no anchor id=\"s{s4}\" in {THEORY}"),
        "README.md:2: link `docs/nothing.md`: no such file".to_string(),
        format!("README.md:2: link `docs/theory.md#s{s4}`: no anchor `s{s4}` in {THEORY}"),
        "README.md:3: link `../outside`: no such file".to_string(),
        format!("crates/x/src/lib.rs:2: §{s21} has no anchor id=\"s{s21}\" in {THEORY}"),
        format!(
            "crates/x/src/lib.rs:3: refers to `{}` outside the repository (cite {THEORY})",
            FORBIDDEN[0]
        ),
        format!(
            "crates/x/src/lib.rs:4: refers to `{}` outside the repository (cite {THEORY})",
            FORBIDDEN[3]
        ),
        format!("crates/x/src/lib.rs:5: §{s7} has no anchor id=\"s{s7}\" in {THEORY}"),
        format!("crates/x/src/lib.rs:5: §{s99} has no anchor id=\"s{s99}\" in {THEORY}"),
        format!("{THEORY}:6: §1.3 has no anchor id=\"s1.3\" in {THEORY}"),
    ];
    assert_eq!(found, expected);

    // Clean input gives nothing; a word ending in "spec" is not a citation.
    let clean = vec![
        (THEORY.to_string(), theory.replace(" and §1.3", "")),
        ("a.rs".to_string(), format!("// ArxPhaseLag{}", FORBIDDEN[3])),
    ];
    assert_eq!(problems(&clean, &|_| true, &|_| None), Vec::<String>::new());
}
