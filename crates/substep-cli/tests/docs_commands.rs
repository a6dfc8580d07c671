//! Docs that run as written (issue 29, item 4), the shell half: every `substep …` command in a
//! fenced ```` ```sh ````, ```` ```bash ````, ```` ```shell ````, ```` ```console ```` or bare
//! ```` ``` ```` block of `README.md` and `docs/*.md` names subcommands and options the binary
//! has. The commands are not run: `substep <subcommand…> --help` is run once per subcommand
//! path, and each `--option` (and `-x`) of a command must be listed in the options of the help
//! of the subcommand it follows. All failures are reported at once with `file:line`. (The TOML
//! blocks are checked by `crates/substep/tests/docs_examples.rs`.)
//!
//! A command is a line that starts with `substep ` (after an optional `$ ` prompt and
//! `NAME=value` assignments), or `cargo run [cargo options] -- ARGS` without `--example`, `--bin`
//! or `-p` naming another target (the workspace's default binary is `substep`). A trailing `\`
//! joins the next line; in a bare block (usage synopses) an indented line continues the command
//! above it. Words are split as a shell does (quotes, `\`), a word starting with `#` ends the
//! command, and the brackets of synopsis notation (`[--quick]`) are dropped. Every option is
//! checked against the default build.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Languages of the fenced blocks whose commands are checked (`""`: a bare fence).
const SHELL_LANGS: [&str; 5] = ["sh", "bash", "shell", "console", ""];

/// The fenced blocks of `md` as `(language, lines as (1-based line, text without the fence's
/// indentation))`; unclosed blocks are dropped (the TOML test reports them).
fn fenced_blocks(md: &str) -> Vec<(String, Vec<(usize, String)>)> {
    let lines: Vec<&str> = md.lines().collect();
    let mut blocks = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let trimmed = lines[i].trim_start();
        let c = trimmed.chars().next().filter(|c| *c == '`' || *c == '~');
        let n = c.map_or(0, |c| trimmed.chars().take_while(|&x| x == c).count());
        if n < 3 {
            i += 1;
            continue;
        }
        let c = c.unwrap();
        let indent = lines[i].len() - trimmed.len();
        let lang = trimmed[n..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .to_ascii_lowercase();
        let mut body = Vec::new();
        i += 1;
        let mut closed = false;
        while i < lines.len() {
            let t = lines[i].trim();
            if t.len() >= n && t.chars().all(|x| x == c) {
                closed = true;
                break;
            }
            let l = lines[i];
            let strip = (l.len() - l.trim_start().len()).min(indent);
            body.push((i + 1, l[strip..].to_string()));
            i += 1;
        }
        if closed {
            blocks.push((lang, body));
        }
        i += 1;
    }
    blocks
}

/// Split `line` into words as a shell does (quotes, backslash escapes); a word that starts with
/// `#` ends it, and so does a control operator (`|`, `;`, `&&`, `||`, `>`).
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            '#' if !in_word => break,
            '\'' => {
                in_word = true;
                for q in chars.by_ref() {
                    if q == '\'' {
                        break;
                    }
                    word.push(q);
                }
            }
            '"' => {
                in_word = true;
                while let Some(q) = chars.next() {
                    match q {
                        '"' => break,
                        '\\' => word.extend(chars.next()),
                        q => word.push(q),
                    }
                }
            }
            '\\' => {
                in_word = true;
                word.extend(chars.next());
            }
            c => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        words.push(word);
    }
    let end = words
        .iter()
        .position(|w| ["|", "||", "&&", ";", ">", ">>", "&"].contains(&w.as_str()))
        .unwrap_or(words.len());
    words.truncate(end);
    words
}

/// The arguments given to the `substep` binary by `words`, if it is a substep command.
fn substep_args(words: &[String]) -> Option<Vec<String>> {
    let start = words
        .iter()
        .position(|w| !(w.contains('=') && !w.starts_with('-') && w.split('=').next().is_some_and(is_name)))?;
    let words = &words[start..];
    match words.first().map(String::as_str) {
        Some("substep") => Some(words[1..].to_vec()),
        Some("cargo") if words.get(1).is_some_and(|w| w == "run") => {
            let dash = words.iter().position(|w| w == "--")?;
            let cargo = &words[2..dash];
            for (i, w) in cargo.iter().enumerate() {
                let next = cargo.get(i + 1).map(String::as_str);
                let other = match w.as_str() {
                    "--example" => true,
                    "--bin" => next != Some("substep"),
                    "-p" | "--package" => next != Some("substep-cli"),
                    _ => false,
                };
                if other {
                    return None;
                }
            }
            Some(words[dash + 1..].to_vec())
        }
        _ => None,
    }
}

fn is_name(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// A command in the docs: `(line, words of the whole line)`.
fn commands(md: &str) -> Vec<(usize, Vec<String>)> {
    let mut out = Vec::new();
    for (lang, body) in fenced_blocks(md) {
        if !SHELL_LANGS.contains(&lang.as_str()) {
            continue;
        }
        let bare = lang.is_empty();
        let mut i = 0;
        while i < body.len() {
            let (line_no, first) = &body[i];
            let mut text = first
                .trim_start()
                .strip_prefix("$ ")
                .unwrap_or(first.trim_start())
                .to_string();
            i += 1;
            // `\` continuations, and in a synopsis the indented lines below.
            loop {
                if let Some(head) = text.trim_end().strip_suffix('\\') {
                    text = head.to_string();
                } else if !(bare && body.get(i).is_some_and(|(_, l)| l.starts_with(char::is_whitespace))) {
                    break;
                }
                match body.get(i) {
                    Some((_, next)) => {
                        text.push(' ');
                        text.push_str(next.trim());
                        i += 1;
                    }
                    None => break,
                }
            }
            if let Some(args) = substep_args(&shell_words(&text)) {
                out.push((*line_no, args));
            }
        }
    }
    out
}

/// What `substep <path> --help` says.
struct Help {
    commands: Vec<String>,
    /// Long (`--out`) and short (`-q`) options, with whether they take a value.
    options: BTreeMap<String, bool>,
    has_arguments: bool,
    needs_command: bool,
}

fn parse_help(text: &str) -> Help {
    let mut help = Help {
        commands: Vec::new(),
        options: BTreeMap::new(),
        has_arguments: false,
        needs_command: false,
    };
    let mut section = "";
    for line in text.lines() {
        if let Some(usage) = line.strip_prefix("Usage:") {
            help.needs_command = usage.contains("<COMMAND>");
            continue;
        }
        if !line.starts_with(' ') && line.ends_with(':') {
            section = line;
            if line == "Arguments:" {
                help.has_arguments = true;
            }
            continue;
        }
        let t = line.trim_start();
        if section == "Commands:" && line.starts_with("  ") && !line.starts_with("      ") {
            if let Some(name) = t.split_whitespace().next() {
                help.commands.push(name.to_string());
            }
        } else if t.starts_with('-') {
            let words: Vec<&str> = t.split_whitespace().collect();
            let mut names = Vec::new();
            let mut takes_value = false;
            for w in &words {
                if w.starts_with('-') {
                    names.push(w.trim_end_matches(','));
                } else {
                    takes_value = w.starts_with('<');
                    break;
                }
            }
            for n in names {
                help.options.insert(n.to_string(), takes_value);
            }
        }
    }
    help
}

/// `substep <path> --help`, parsed, once per path.
struct Helps(BTreeMap<Vec<String>, Help>);

impl Helps {
    fn get(&mut self, path: &[String]) -> &Help {
        self.0.entry(path.to_vec()).or_insert_with(|| {
            let out = Command::new(env!("CARGO_BIN_EXE_substep"))
                .args(path)
                .arg("--help")
                .output()
                .expect("the substep binary runs");
            let text = String::from_utf8_lossy(&out.stdout);
            assert!(
                out.status.success(),
                "substep {} --help failed: {}",
                path.join(" "),
                String::from_utf8_lossy(&out.stderr)
            );
            parse_help(&text)
        })
    }
}

/// Check one command's arguments; a failure names the subcommand and the word.
fn check_args(helps: &mut Helps, args: &[String], checked_options: &mut usize) -> Result<Vec<String>, String> {
    let mut path: Vec<String> = Vec::new();
    let mut positional = false;
    let mut i = 0;
    let show = |p: &[String]| {
        if p.is_empty() {
            "substep".to_string()
        } else {
            format!("substep {}", p.join(" "))
        }
    };
    while i < args.len() {
        let word = args[i].trim_start_matches('[').trim_end_matches(']');
        i += 1;
        if word == "--" {
            break;
        }
        let help = helps.get(&path);
        let option = if word.starts_with("--") {
            Some(word.split('=').next().unwrap())
        } else if word.len() == 2 && word.starts_with('-') && word.as_bytes()[1].is_ascii_alphabetic() {
            Some(word)
        } else {
            None
        };
        if let Some(option) = option {
            *checked_options += 1;
            match help.options.get(option) {
                Some(&takes_value) => {
                    if takes_value && !word.contains('=') {
                        i += 1;
                    }
                }
                None => {
                    return Err(format!(
                        "`{}` has no option `{option}` (see `{} --help`)",
                        show(&path),
                        show(&path)
                    ));
                }
            }
        } else if !positional && help.commands.iter().any(|c| c == word) {
            path.push(word.to_string());
        } else if !positional && !help.commands.is_empty() && !help.has_arguments {
            return Err(format!(
                "`{}` has no subcommand `{word}` (it has {})",
                show(&path),
                help.commands.join(", ")
            ));
        } else {
            positional = true;
        }
    }
    if helps.get(&path).needs_command {
        return Err(format!("`{}` needs a subcommand", show(&path)));
    }
    Ok(path)
}

/// Check the commands of one markdown file: `(commands checked, failures as name:line: …)`.
fn check_markdown(
    helps: &mut Helps,
    name: &str,
    md: &str,
    paths: &mut BTreeMap<String, usize>,
    options: &mut usize,
) -> (usize, Vec<String>) {
    let cmds = commands(md);
    let mut failures = Vec::new();
    for (line, args) in &cmds {
        match check_args(helps, args, options) {
            Ok(path) => *paths.entry(path.join(" ")).or_default() += 1,
            Err(e) => failures.push(format!("{name}:{line}: {e}")),
        }
    }
    (cmds.len(), failures)
}

fn doc_files() -> Vec<(String, PathBuf)> {
    let root = repo_root();
    let mut files = vec![("README.md".to_string(), root.join("README.md"))];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
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

#[test]
fn every_substep_command_in_the_docs_has_its_subcommands_and_options() {
    let mut helps = Helps(BTreeMap::new());
    let mut paths = BTreeMap::new();
    let (mut n, mut options) = (0, 0);
    let mut failures = Vec::new();
    for (name, path) in doc_files() {
        let md = std::fs::read_to_string(&path).unwrap();
        let (k, f) = check_markdown(&mut helps, &name, &md, &mut paths, &mut options);
        n += k;
        failures.extend(f);
    }
    println!(
        "{n} commands, {options} options checked, {} help texts read; subcommand paths: {paths:?}",
        helps.0.len()
    );
    assert!(
        failures.is_empty(),
        "{} command(s) in the docs the binary does not have:\n{}",
        failures.len(),
        failures.join("\n")
    );
    // The docs hold about 50 commands; far fewer means the extraction broke.
    assert!(n >= 40 && options >= 50, "only {n} commands, {options} options found");
    for p in ["run", "analyze stability", "bench", "site serve", "benchmark rths"] {
        assert!(paths.contains_key(p), "no `substep {p}` command found: {paths:?}");
    }
}

/// The checker itself: bad commands planted in memory are reported with their lines.
#[test]
fn the_checker_reports_unknown_subcommands_and_options_with_their_lines() {
    let md = "\
# t

```sh
substep run CONFIG --quiet --no-plots          # fine
substep run CONFIG --quite                     # line 5: typo
cargo run --release -- bench --modle chain     # line 6
cargo run --release --example frame_solve -- --anything   # not the substep binary
```

```
$ substep analyze stabilty
substep analyze plan CONFIG.toml [--dt 0.01] \\
    [--k-sub 1,2] [--tolerence 0.02]
substep vst [--out DIR] [--quick]
    [--no-plot]
```

```console
$ substep analyze
$ substep site serve site.toml --out x
```
";
    let mut helps = Helps(BTreeMap::new());
    let (mut paths, mut options) = (BTreeMap::new(), 0);
    let (n, failures) = check_markdown(&mut helps, "t.md", md, &mut paths, &mut options);
    let report = failures.join("\n");
    for (prefix, needle) in [
        ("t.md:5: ", "`substep run` has no option `--quite`"),
        ("t.md:6: ", "`substep bench` has no option `--modle`"),
        ("t.md:11: ", "`substep analyze` has no subcommand `stabilty`"),
        ("t.md:12: ", "`substep analyze plan` has no option `--tolerence`"),
        ("t.md:14: ", "`substep vst` has no option `--no-plot`"),
        ("t.md:19: ", "`substep analyze` needs a subcommand"),
        ("t.md:20: ", "`substep site serve` has no option `--out`"),
    ] {
        assert!(
            failures.iter().any(|f| f.starts_with(prefix) && f.contains(needle)),
            "no `{prefix}… {needle}` in:\n{report}"
        );
    }
    assert_eq!((n, failures.len()), (8, 7), "{report}");
    assert_eq!(shell_words("a 'b c' \"d\\\"e\" f\\ g # h"), ["a", "b c", "d\"e", "f g"]);
}
