//! Docs that run as written (issue 29, item 4): every fenced ```` ```toml ```` block in
//! `README.md` and `docs/*.md` is read by the parser of the file it shows, and no doc or example
//! holds a merge-conflict marker. All failures are reported at once, each with the `file:line` of
//! its block's opening fence. A unit test at the end plants bad blocks in memory and checks that
//! they are reported with their lines, so the repository check cannot pass by finding nothing.
//! (The shell commands of the docs are checked against the binary's `--help` by
//! `crates/substep-cli/tests/docs_commands.rs`.)
//!
//! How a block is checked:
//!
//! 1. It must be valid TOML. The only way out is a comment on the line right before the fence,
//!    `<!-- docs-example: skip (reason) -->`, for a block that is partial or illustrative on
//!    purpose (it is then not read at all).
//! 2. It is classified by its top-level keys:
//!    * `[site]`: a site file (`substep site serve`), read by `SiteDefinition::from_toml`;
//!      without `[[specimen]]` it is a fragment of one, put over `examples/sites/tmd_site.toml`
//!      (as below);
//!    * `base`, `[grid]`, `[samples]`, `seeds`, `seed_key` or `metrics`: a study file, read by
//!      `Study::from_json` with its `base` file, and its first variant's test definition is
//!      built;
//!    * only tables of a test definition (the key list comes from the parser itself), with all
//!      three required ones (`[structure]`, `[ground_motion]`, `[integrator]`): a complete test
//!      definition, read by `TestDefinition::from_toml`;
//!    * only tables of a test definition, not all required ones: a fragment. It is put over
//!      `examples/default.toml` (or over the file named by `<!-- docs-example: base FILE -->` on
//!      the line before the fence) and the result must be accepted by
//!      `TestDefinition::from_toml`. Putting over: a table of the fragment that has keys of its
//!      own replaces the own keys of the base's table of that name (a table documents one whole
//!      setting, e.g. an actuator `kind` and its keys) and keeps the base's sub-tables; a table
//!      with sub-tables only (`substructure` in `[substructure.phase_lag]`) just leads to them;
//!      an array of tables (`[[substructure.specimen]]`) replaces the base's array; a fragment
//!      with a model form (`mass`/`stiffness`, `shear_building`, `storeys`, `frame`, `sdof`, `tmd`)
//!      replaces the base's whole `[structure]` (the forms exclude each other);
//!    * a maRTHS settings file (`[coupler]`, or `[plant]` with its matrix `h`; besides them only
//!      `[controller]` and `[substep]`): read by `MarthsConfig::from_toml`;
//!    * only the tables of a benchmark settings file (`[controller]`, `[plant]`, `[noise]`,
//!      `[substep]`): read by `BenchmarkConfig::parse`;
//!    * anything else fails unless it is listed in [`UNCLASSIFIED`] with a reason.
//! 3. Relative paths (records, matrices, secret files): a block is read as if it were a file
//!    in the repository root, then in `examples/`, `examples/studies/`, `examples/sites/` (the
//!    first that accepts it wins), and last in a scratch directory holding the stand-ins of
//!    [`STAND_INS`] for the files the docs name but the repository does not ship.
//! 4. A block whose first line is a comment naming a file of the repository (`# examples/...`)
//!    shows that file: every value the block gives must equal the file's.
//!
//! Parser messages of a standalone block carry the line number in the doc (the block is read
//! with its fence's line offset); a fragment's message names the key.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use substep::benchmark::rths::{BenchmarkConfig, CONFIG_KEYS as BENCHMARK_KEYS};
use substep::io::TestDefinition;
use substep::io::site_config::SiteDefinition;
use substep::study::Study;
use toml::{Table, Value};

/// The base of fragments of a test definition without a `base` directive.
const DEFAULT_BASE: &str = "examples/default.toml";

/// The base of fragments of a site file (`[site]` without `[[specimen]]`).
const DEFAULT_SITE_BASE: &str = "examples/sites/tmd_site.toml";

/// Directories (relative to the repository root) a block's relative paths are tried against,
/// in order; the stand-in directory comes last.
const SEARCH_DIRS: [&str; 4] = ["", "examples", "examples/studies", "examples/sites"];

/// Files the docs' examples name as the user's own (a record, a matrix, a secret): `(path,
/// contents)`, written to a scratch directory so the rest of those blocks is still checked.
const STAND_INS: &[(&str, &str)] = &[
    // docs/config.md `substep lab emulate`: the test a target file names.
    (
        "my_test.toml",
        concat!(
            include_str!("../../../examples/default.toml"),
            "\n[substructure.lab]\nprotocol = \"substep_udp\"\naddress = \"127.0.0.1:5000\"\n"
        ),
    ),
    // docs/config.md `[structure]`: `stiffness = "K.mtx"` next to a 2×2 inline mass.
    (
        "K.mtx",
        "%%MatrixMarket matrix array real symmetric\n2 2\n41452.34\n-1973.92\n1973.92\n",
    ),
    // docs/config.md `[ground_motion]`: a PEER record (values in g).
    (
        "records/elcentro.AT2",
        "PEER NGA STRONG MOTION DATABASE RECORD\nSTAND-IN\nACCELERATION TIME SERIES IN UNITS OF G\n\
         NPTS=    4, DT=   .0100 SEC\n  .1000000E-01  -.2000000E-01   .5000000E-02  0.0000000E+00\n",
    ),
    // docs/config.md `[ground_motion]`: a two-column record in g.
    (
        "records/kobe_g.csv",
        "t,a_g\n0.0,0.0\n0.01,0.01\n0.02,-0.02\n0.03,0.0\n",
    ),
    // docs/security.md: the shared secret of a site and its clients (64 hex digits).
    (
        "site.key",
        "3f6b1c9a0d2e4f5a6b7c8d9e0f1a2b3c4d5e6f708192a3b4c5d6e7f8091a2b3c\n",
    ),
];

/// TOML blocks that are none of the known kinds, on purpose: `(doc file, a line of the block,
/// reason)`. Empty: every block in the docs is one of the kinds above.
const UNCLASSIFIED: &[(&str, &str, &str)] = &[];

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

// --- Markdown -----------------------------------------------------------------------------------

/// What the comment on the line before a fence asks.
#[derive(Debug, Clone, PartialEq)]
enum Directive {
    /// `<!-- docs-example: skip (reason) -->`
    Skip(String),
    /// `<!-- docs-example: base FILE -->`: the base of a fragment (relative to the repo root).
    Base(String),
}

/// A fenced code block.
#[derive(Debug)]
struct Block {
    /// 1-based line of the opening fence.
    line: usize,
    /// First word of the info string, lower case (`""` for a bare fence).
    lang: String,
    /// The lines between the fences, without the fence's indentation.
    text: String,
    directive: Option<Directive>,
}

const DIRECTIVE: &str = "<!-- docs-example:";

fn parse_directive(line: &str) -> Result<Directive, String> {
    let body = line
        .trim()
        .strip_prefix(DIRECTIVE)
        .and_then(|r| r.strip_suffix("-->"))
        .map(str::trim)
        .ok_or_else(|| format!("malformed directive `{}`", line.trim()))?;
    if let Some(reason) = body.strip_prefix("skip") {
        let reason = reason.trim();
        match reason.strip_prefix('(').and_then(|r| r.strip_suffix(')')) {
            Some(r) if !r.trim().is_empty() => Ok(Directive::Skip(r.trim().to_string())),
            _ => Err(format!(
                "`{}`: a skip needs a reason, `{DIRECTIVE} skip (why) -->`",
                line.trim()
            )),
        }
    } else if let Some(file) = body.strip_prefix("base ") {
        Ok(Directive::Base(file.trim().to_string()))
    } else {
        Err(format!(
            "`{}`: unknown directive (skip (reason) or base FILE)",
            line.trim()
        ))
    }
}

/// The fenced blocks of `md`, and problems as `(line, message)`: an unclosed fence, a
/// directive that is malformed or not right before a fence.
fn fenced_blocks(md: &str) -> (Vec<Block>, Vec<(usize, String)>) {
    let lines: Vec<&str> = md.lines().collect();
    let mut blocks = Vec::new();
    let mut problems = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        let trimmed = line.trim_start();
        let fence_char = trimmed.chars().next().filter(|c| *c == '`' || *c == '~');
        let fence_len = fence_char.map_or(0, |c| trimmed.chars().take_while(|&x| x == c).count());
        if trimmed.starts_with(DIRECTIVE) {
            let next_is_fence = lines
                .get(i + 1)
                .is_some_and(|l| l.trim_start().starts_with("```") || l.trim_start().starts_with("~~~"));
            if !next_is_fence {
                problems.push((
                    i + 1,
                    format!("`{}` is not on the line right before a fence", line.trim()),
                ));
            }
        }
        if fence_len < 3 {
            i += 1;
            continue;
        }
        let c = fence_char.unwrap();
        let indent = line.len() - trimmed.len();
        let lang = trimmed[fence_len..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .trim_matches(|c| c == '{' || c == '}' || c == '.')
            .to_ascii_lowercase();
        let directive = match i.checked_sub(1).map(|p| lines[p]) {
            Some(prev) if prev.trim_start().starts_with(DIRECTIVE) => match parse_directive(prev) {
                Ok(d) => Some(d),
                Err(e) => {
                    problems.push((i, e));
                    None
                }
            },
            _ => None,
        };
        let start = i;
        let mut text = String::new();
        i += 1;
        let mut closed = false;
        while i < lines.len() {
            let t = lines[i].trim();
            if t.len() >= fence_len && t.chars().all(|x| x == c) {
                closed = true;
                break;
            }
            let l = lines[i];
            let strip = l.len() - l.trim_start().len();
            text.push_str(&l[strip.min(indent)..]);
            text.push('\n');
            i += 1;
        }
        if closed {
            blocks.push(Block {
                line: start + 1,
                lang,
                text,
                directive,
            });
        } else {
            problems.push((start + 1, "code block is never closed".to_string()));
        }
        i += 1;
    }
    (blocks, problems)
}

/// Lines of `text` that start with a merge-conflict marker, as `name:line: ...`.
fn conflict_markers(name: &str, text: &str) -> Vec<String> {
    let (open, close) = ("<".repeat(7), ">".repeat(7));
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with(&open) || l.starts_with(&close))
        .map(|(i, l)| format!("{name}:{}: merge-conflict marker `{}`", i + 1, l.trim_end()))
        .collect()
}

// --- checking TOML blocks -------------------------------------------------------------------------

/// What a block was checked as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    TestDefinition,
    Fragment,
    Site,
    SiteFragment,
    Study,
    Benchmark,
    Marths,
    LabEmulator,
    Skipped,
    Listed,
}

/// What the checker needs besides the markdown.
struct Checker {
    root: PathBuf,
    /// Directories relative paths are tried against, in order.
    dirs: Vec<PathBuf>,
    /// Top-level tables of a test definition, from the parser's unknown-field message.
    test_keys: Vec<String>,
}

impl Checker {
    fn new() -> Self {
        let root = repo_root();
        let scratch = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("docs-examples-{}", std::process::id()));
        for (rel, contents) in STAND_INS {
            let path = scratch.join(rel);
            fs::create_dir_all(path.parent().unwrap()).unwrap();
            fs::write(&path, contents).unwrap();
        }
        let mut dirs: Vec<PathBuf> = SEARCH_DIRS.iter().map(|d| root.join(d)).collect();
        dirs.push(scratch);
        Self {
            root,
            dirs,
            test_keys: test_definition_keys(),
        }
    }

    /// The first directory of `dirs` (after `first`, if given) in which `parse` accepts the
    /// block, else the most telling message: the first that is not about a missing file.
    fn in_some_dir<T>(&self, first: Option<&Path>, parse: impl Fn(&Path) -> Result<T, String>) -> Result<T, String> {
        let mut errors = Vec::new();
        for dir in first.into_iter().chain(self.dirs.iter().map(PathBuf::as_path)) {
            match parse(dir) {
                Ok(v) => return Ok(v),
                Err(e) => errors.push(e),
            }
        }
        let missing = |e: &String| e.contains("No such file") || e.contains("os error 2");
        Err(errors.iter().find(|e| !missing(e)).unwrap_or(&errors[0]).clone())
    }

    /// Check one markdown file; `name` names it in messages. Returns what each TOML block was
    /// checked as and the failures (`name:line: message`).
    fn check_markdown(&self, name: &str, md: &str) -> (Vec<Kind>, Vec<String>) {
        let (blocks, problems) = fenced_blocks(md);
        let mut failures: Vec<String> = problems.into_iter().map(|(l, m)| format!("{name}:{l}: {m}")).collect();
        failures.extend(conflict_markers(name, md));
        let mut kinds = Vec::new();
        for b in blocks {
            if b.lang != "toml" {
                if matches!(b.directive, Some(Directive::Base(_))) {
                    failures.push(format!("{name}:{}: a base directive on a `{}` block", b.line, b.lang));
                }
                continue;
            }
            match self.check_block(name, &b) {
                Ok(kind) => kinds.push(kind),
                Err(message) => failures.push(format!("{name}:{}: {message}", b.line)),
            }
        }
        (kinds, failures)
    }

    fn check_block(&self, name: &str, b: &Block) -> Result<Kind, String> {
        if let Some(Directive::Skip(_)) = &b.directive {
            return Ok(Kind::Skipped);
        }
        // Read at the fence's offset, so that a parser's `line N` is the doc's line.
        let text = format!("{}{}", "\n".repeat(b.line), b.text);
        let table: Table = toml::from_str(&text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start].matches('\n').count() + 1);
            let msg = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
            match line {
                Some(l) => format!("not valid TOML: line {l}: {msg}"),
                None => format!("not valid TOML: {msg}"),
            }
        })?;
        self.shows_file(&b.text, &table)?;
        let keys: Vec<&str> = table.keys().map(String::as_str).collect();
        let base = match &b.directive {
            Some(Directive::Base(f)) => Some(f.as_str()),
            _ => None,
        };
        let listed = UNCLASSIFIED
            .iter()
            .any(|(file, line, _)| *file == name && b.text.lines().any(|l| l.trim() == line.trim()));
        let is_test_key = |k: &&str| self.test_keys.iter().any(|t| t == k);
        let kind = if keys.contains(&"site") {
            if keys.contains(&"specimen") {
                Kind::Site
            } else {
                Kind::SiteFragment
            }
        } else if keys
            .iter()
            .any(|k| ["base", "grid", "samples", "seeds", "seed_key", "metrics"].contains(k))
        {
            Kind::Study
        } else if !keys.is_empty() && keys.iter().all(is_test_key) {
            if ["structure", "ground_motion", "integrator"]
                .iter()
                .all(|k| keys.contains(k))
            {
                Kind::TestDefinition
            } else {
                Kind::Fragment
            }
        } else if !keys.is_empty()
            && keys
                .iter()
                .all(|k| ["plant", "coupler", "controller", "substep"].contains(k))
            && (keys.contains(&"coupler")
                || table
                    .get("plant")
                    .and_then(Value::as_table)
                    .is_some_and(|p| p.contains_key("h")))
        {
            Kind::Marths
        } else if !keys.is_empty() && keys.iter().all(|k| BENCHMARK_KEYS.contains(k)) {
            Kind::Benchmark
        } else if keys.contains(&"test") && keys.iter().all(|k| ["test", "bind", "idle", "faults"].contains(k)) {
            Kind::LabEmulator
        } else if listed {
            return Ok(Kind::Listed);
        } else {
            return Err(format!(
                "a TOML block of no known kind (top-level keys {keys:?}): make it a test \
                 definition, fragment, site, study or benchmark file, or list it in UNCLASSIFIED"
            ));
        };
        if base.is_some() && !matches!(kind, Kind::Fragment | Kind::SiteFragment) {
            return Err(format!(
                "a base directive on a {kind:?} block (only fragments have a base)"
            ));
        }
        match kind {
            Kind::TestDefinition => self
                .in_some_dir(None, |dir| {
                    TestDefinition::from_toml(&text, name, dir)
                        .map(drop)
                        .map_err(|e| e.to_string())
                })
                .map_err(|e| format!("test definition: {e}"))?,
            Kind::Fragment => self.check_fragment(name, b.line, &table, base.unwrap_or(DEFAULT_BASE), |t, n, d| {
                TestDefinition::from_toml(t, n, d).map(drop).map_err(|e| e.to_string())
            })?,
            Kind::SiteFragment => {
                self.check_fragment(name, b.line, &table, base.unwrap_or(DEFAULT_SITE_BASE), |t, n, d| {
                    SiteDefinition::from_toml(t, n, d).map(drop).map_err(|e| e.to_string())
                })?
            }
            Kind::Site => self
                .in_some_dir(None, |dir| {
                    SiteDefinition::from_toml(&text, name, dir)
                        .map(drop)
                        .map_err(|e| e.to_string())
                })
                .map_err(|e| format!("site file: {e}"))?,
            Kind::Study => self.check_study(name, &table)?,
            Kind::Benchmark => BenchmarkConfig::parse(&text, name)
                .map(drop)
                .map_err(|e| format!("benchmark settings: {e}"))?,
            Kind::Marths => substep::benchmark::marths::MarthsConfig::from_toml(&text, name)
                .map(drop)
                .map_err(|e| format!("maRTHS settings: {e}"))?,
            Kind::LabEmulator => self
                .in_some_dir(None, |dir| {
                    substep::io::config::emulator_from_toml(&text, name, dir)
                        .map(drop)
                        .map_err(|e| e.to_string())
                })
                .map_err(|e| format!("lab emulator target file: {e}"))?,
            Kind::Skipped | Kind::Listed => unreachable!(),
        }
        Ok(kind)
    }

    /// Rule 4: a block that starts with `# FILE`, FILE a file of the repository, gives only
    /// values that FILE has.
    fn shows_file(&self, text: &str, block: &Table) -> Result<(), String> {
        let Some(first) = text.lines().next().and_then(|l| l.trim().strip_prefix('#')) else {
            return Ok(());
        };
        let rel = first.trim();
        if rel.contains(char::is_whitespace) || !rel.ends_with(".toml") || !self.root.join(rel).is_file() {
            return Ok(());
        }
        let file: Table =
            toml::from_str(&fs::read_to_string(self.root.join(rel)).unwrap()).unwrap_or_else(|e| panic!("{rel}: {e}"));
        let mut diffs = Vec::new();
        not_in(block, &file, "", &mut diffs);
        if diffs.is_empty() {
            Ok(())
        } else {
            Err(format!(
                "the block says it shows {rel} but differs from it at {}",
                diffs.join(", ")
            ))
        }
    }

    /// Put `fragment` over the file `base_rel` and read the result with `parse(text, name, dir)`.
    fn check_fragment(
        &self,
        name: &str,
        line: usize,
        fragment: &Table,
        base_rel: &str,
        parse: impl Fn(&str, &str, &Path) -> Result<(), String>,
    ) -> Result<(), String> {
        let base_path = self.root.join(base_rel);
        let base_text =
            fs::read_to_string(&base_path).map_err(|e| format!("fragment base {base_rel}: cannot read: {e}"))?;
        let mut config: Table = toml::from_str(&base_text).map_err(|e| format!("fragment base {base_rel}: {e}"))?;
        put_over(&mut config, fragment);
        let merged = toml::to_string(&config).map_err(|e| format!("fragment: cannot write the merged config: {e}"))?;
        let label = format!("{name}:{line} over {base_rel}");
        self.in_some_dir(base_path.parent(), |dir| parse(&merged, &label, dir))
            .map_err(|e| {
                // Line numbers of the merged text would only mislead; the message names the key.
                let e = e.strip_prefix(&format!("{label}: ")).unwrap_or(&e);
                let e = match e.strip_prefix("line ").and_then(|r| r.split_once(": ")) {
                    Some((n, rest)) if n.chars().all(|c| c.is_ascii_digit()) => rest,
                    _ => e,
                };
                format!("fragment over {base_rel}: {e}")
            })
    }

    fn check_study(&self, name: &str, study: &Table) -> Result<(), String> {
        let base = study
            .get("base")
            .and_then(Value::as_str)
            .ok_or_else(|| "study file without `base` (the test definition it varies)".to_string())?;
        let spec = serde_json::to_string(study).map_err(|e| format!("study: {e}"))?;
        self.in_some_dir(None, |dir| {
            let path = dir.join(base);
            let text = fs::read_to_string(&path).map_err(|e| format!("base {}: {e}", path.display()))?;
            let s = Study::from_json(&text, base, dir, &spec).map_err(|e| e.to_string())?;
            let v = s.variant(0).map_err(|e| e.to_string())?;
            s.definition(&v).map(drop).map_err(|e| e.to_string())
        })
        .map_err(|e| format!("study file ({name}): {e}"))
    }
}

/// Dotted paths where `block` gives a value that `file` does not have.
fn not_in(block: &Table, file: &Table, prefix: &str, out: &mut Vec<String>) {
    for (k, v) in block {
        let path = format!("{prefix}{k}");
        match (v, file.get(k)) {
            (Value::Table(b), Some(Value::Table(f))) => not_in(b, f, &format!("{path}."), out),
            (b, Some(f)) if b == f => {}
            _ => out.push(format!("`{path}`")),
        }
    }
}

const MODEL_FORMS: [&str; 7] = ["mass", "stiffness", "shear_building", "storeys", "frame", "sdof", "tmd"];

/// A value of a table's own (not a sub-table, not an array of tables).
fn own(v: &Value) -> bool {
    match v {
        Value::Table(_) => false,
        Value::Array(a) => a.is_empty() || !a.iter().all(Value::is_table),
        _ => true,
    }
}

/// Put `fragment` over `base` (rule 2 of the module docs).
fn put_over(base: &mut Table, fragment: &Table) {
    if let Some(Value::Table(s)) = fragment.get("structure")
        && MODEL_FORMS.iter().any(|k| s.contains_key(*k))
    {
        base.remove("structure");
    }
    merge(base, fragment);
}

fn merge(base: &mut Table, fragment: &Table) {
    for (k, v) in fragment {
        match (base.get_mut(k), v) {
            (Some(Value::Table(b)), Value::Table(f)) => {
                if f.values().any(own) {
                    b.retain(|_, x| !own(x));
                }
                merge(b, f);
            }
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The top-level tables of a test definition, from the parser's unknown-field message.
fn test_definition_keys() -> Vec<String> {
    let err = TestDefinition::from_toml("zzz_not_a_key = 1\n", "probe.toml", Path::new("."))
        .expect_err("the probe key was accepted")
        .to_string();
    let list = err
        .split_once("expected ")
        .map(|(_, rest)| rest.trim_start_matches("one of "))
        .unwrap_or_else(|| panic!("no key list in {err}"));
    let keys: Vec<String> = list
        .split('`')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, k)| k.to_string())
        .collect();
    for k in ["structure", "ground_motion", "integrator", "substructure", "output"] {
        assert!(
            keys.iter().any(|x| x == k),
            "{k} missing from the probed keys {keys:?} ({err})"
        );
    }
    keys
}

// --- the repository -----------------------------------------------------------------------------

/// `README.md` and `docs/*.md`, as `(name relative to the root, path)`, sorted.
fn doc_files(root: &Path) -> Vec<(String, PathBuf)> {
    let mut files = vec![("README.md".to_string(), root.join("README.md"))];
    let mut docs: Vec<PathBuf> = fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(
        docs.into_iter()
            .map(|p| (format!("docs/{}", p.file_name().unwrap().to_string_lossy()), p)),
    );
    files
}

/// Every `*.toml` under `dir`, recursively, sorted.
fn toml_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            toml_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "toml") {
            out.push(p);
        }
    }
}

#[test]
fn every_toml_block_in_the_docs_is_accepted_by_its_parser() {
    let checker = Checker::new();
    let mut counts: BTreeMap<Kind, usize> = BTreeMap::new();
    let mut failures = Vec::new();
    for (name, path) in doc_files(&checker.root) {
        let md = fs::read_to_string(&path).unwrap();
        let (kinds, f) = checker.check_markdown(&name, &md);
        for k in kinds {
            *counts.entry(k).or_default() += 1;
        }
        failures.extend(f);
    }
    let total: usize = counts.values().sum();
    println!("TOML blocks checked: {total} {counts:?}");
    assert!(
        failures.is_empty(),
        "{} problem(s) in the docs' TOML blocks:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // The docs hold about 35 TOML blocks; far fewer means the extraction broke.
    assert!(total >= 30, "only {total} TOML blocks found: {counts:?}");
    assert!(counts.get(&Kind::Fragment).copied().unwrap_or(0) >= 20, "{counts:?}");
    for k in [Kind::Site, Kind::Study, Kind::Benchmark] {
        assert!(counts.contains_key(&k), "no {k:?} block found: {counts:?}");
    }
}

#[test]
fn no_merge_conflict_markers_in_docs_or_examples() {
    let root = repo_root();
    let mut files: Vec<(String, PathBuf)> = doc_files(&root);
    let mut examples = Vec::new();
    toml_files(&root.join("examples"), &mut examples);
    assert!(examples.len() >= 5, "only {} example configs", examples.len());
    files.extend(examples.into_iter().map(|p| {
        let rel = p.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
        (rel, p)
    }));
    let mut failures = Vec::new();
    for (name, path) in &files {
        failures.extend(conflict_markers(name, &fs::read_to_string(path).unwrap()));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The checker itself: bad blocks planted in memory are reported with their lines.
#[test]
fn the_checker_reports_each_bad_block_with_its_line() {
    let checker = Checker::new();
    let open = "<".repeat(7);
    let md = format!(
        "# A doc\n\
         \n\
         ```toml\n\
         [output]\n\
         plots = false\n\
         ```\n\
         \n\
         ```toml\n\
         [output]\n\
         dirr = \"x\"\n\
         ```\n\
         {open} HEAD\n\
         <!-- docs-example: skip (an excerpt) -->\n\
         ```toml\n\
         [output]\n\
         ...\n\
         ```\n\
         ```toml\n\
         [structure.sdof]\n\
         mass = 1.0\n\
         stiffness = 1.0\n\
         [ground_motion]\n\
         generator = \"harmonic\"\n\
         amplitude = 1.0\n\
         frequency = 1.0\n\
         duration = 1.0\n\
         [integrator]\n\
         dt = 0.01\n\
         shceme = \"hht\"\n\
         ```\n\
         ```toml\n\
         [substructure.actuator]\n\
         kind = \"ideal\"\n\
         [substructure.actuator]\n\
         kind = \"delay\"\n\
         ```\n\
         ```toml\n\
         [substructure.phase_lag]\n\
         kind = \"arx\"\n\
         n_u = 99\n\
         ```\n\
         ```toml\n\
         [site]\n\
         protocol = \"substep\"\n\
         listen = \"127.0.0.1:8090\"\n\
         [[specimen]]\n\
         kind = \"linear_sdof\"\n\
         dof = 1\n\
         stiffness = 1.0\n\
         ```\n\
         ```toml\n\
         [controller]\n\
         kind = \"arx\"\n\
         feedforward = {{ num = [1.0], den = [1.0, 1.0] }}\n\
         ```\n\
         ```toml\n\
         [weather]\n\
         rain = true\n\
         ```\n\
         <!-- docs-example: skp (typo) -->\n\
         ```toml\n\
         [output]\n\
         plots = false\n\
         ```\n\
         <!-- docs-example: base examples/two_specimens.toml -->\n\
         ```toml\n\
         [substructure]\n\
         coupling_dofs = [1, 3]\n\
         substeps = 5\n\
         ```\n\
         ```toml\n\
         [substructure]\n\
         coupling_dofs = [1, 3]\n\
         substeps = 5\n\
         ```\n\
         ```toml\n\
         # examples/studies/monte_carlo.toml\n\
         base = \"tmd_base.toml\"\n\
         metrics = [\"tracking_delay\"]\n\
         ```\n\
         ```toml\n\
         base = \"tmd_base.toml\"\n\
         metric = [\"tracking_delay\"]\n\
         ```\n\
         ```toml\n\
         [output]\n"
    );
    let (kinds, failures) = checker.check_markdown("t.md", &md);
    let report = failures.join("\n");
    let expect = |prefix: &str, needle: &str| {
        assert!(
            failures.iter().any(|f| f.starts_with(prefix) && f.contains(needle)),
            "no `{prefix} … {needle}` in:\n{report}"
        );
    };
    expect("t.md:8: ", "unknown field `dirr`");
    expect("t.md:12: ", "merge-conflict marker");
    expect("t.md:18: ", "line 29: unknown field `shceme`");
    expect("t.md:31: ", "not valid TOML: line 34");
    expect("t.md:37: ", "phase_lag.n_u");
    expect("t.md:51: ", "not both");
    expect("t.md:56: ", "no known kind");
    expect("t.md:60: ", "unknown directive");
    expect("t.md:71: ", "coupling_dofs: DOF 3 is out of range");
    expect("t.md:76: ", "differs from it at `metrics`");
    expect("t.md:81: ", "unknown field `metric`");
    expect("t.md:85: ", "never closed");
    assert_eq!(failures.len(), 12, "{report}");
    // The good block, the skipped one, the site, the block after the bad directive, the
    // fragment over its own base.
    assert_eq!(
        kinds,
        [
            Kind::Fragment,
            Kind::Skipped,
            Kind::Site,
            Kind::Fragment,
            Kind::Fragment
        ],
        "{report}"
    );
}

#[test]
fn fragments_replace_a_tables_own_keys_and_keep_its_sub_tables() {
    let mut base: Table = toml::from_str(
        "[structure.sdof]\nmass = 1.0\n[substructure]\ncoupling_dofs = [1]\nsubsteps = 4\n\
         [[substructure.specimen]]\ndof = 1\n[substructure.actuator]\nkind = \"second_order\"\nzeta = 0.7\n",
    )
    .unwrap();
    let fragment: Table =
        toml::from_str("[substructure]\nsubsteps = 5\n[substructure.actuator]\nkind = \"ideal\"\n[structure.tmd]\n")
            .unwrap();
    put_over(&mut base, &fragment);
    let want: Table = toml::from_str(
        "[structure.tmd]\n[substructure]\nsubsteps = 5\n[[substructure.specimen]]\ndof = 1\n\
         [substructure.actuator]\nkind = \"ideal\"\n",
    )
    .unwrap();
    assert_eq!(base, want);
}
