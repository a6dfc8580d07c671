//! What can be checked automatically about the figures a user puts in a paper (issue 29): every
//! figure kind of every command is drawn as SVG, and for each text element (from plotters' SVG:
//! position, anchor, font size) this checks that
//! * it lies inside the canvas (widths estimated at 0.62 em per character, DejaVu Sans' mean
//!   advance for digits and lower case is 0.55–0.64 em);
//! * tick labels of one axis are all different (no "7.3, 7.3, 7.5") and do not overlap;
//! * axis titles carry a unit in brackets where the quantity has one.
//!
//! The checker itself is checked on hand-written SVG with each defect.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(Debug, Clone)]
struct Text {
    x: f64,
    y: f64,
    size: f64,
    anchor: String,
    dy: String,
    /// `rotate(angle, …)` of the element (0: none).
    rotation: i32,
    content: String,
}

fn attr(tag: &str, name: &str) -> Option<String> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let end = tag[start..].find('"')? + start;
    Some(tag[start..end].to_string())
}

/// `(width, height, texts)` of a plotters SVG.
fn parse(svg: &str) -> (f64, f64, Vec<Text>) {
    let head = &svg[..svg.find('>').unwrap()];
    let w: f64 = attr(head, "width").unwrap().parse().unwrap();
    let h: f64 = attr(head, "height").unwrap().parse().unwrap();
    let mut texts = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find("<text ") {
        let tag_end = rest[i..].find('>').unwrap() + i;
        let tag = &rest[i..tag_end];
        let close = rest[tag_end..].find("</text>").unwrap() + tag_end;
        let content = rest[tag_end + 1..close]
            .trim()
            .replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&amp;", "&");
        texts.push(Text {
            x: attr(tag, "x").unwrap().parse().unwrap(),
            y: attr(tag, "y").unwrap().parse().unwrap(),
            size: attr(tag, "font-size").unwrap().parse().unwrap(),
            anchor: attr(tag, "text-anchor").unwrap_or_else(|| "start".into()),
            dy: attr(tag, "dy").unwrap_or_default(),
            rotation: attr(tag, "transform")
                .and_then(|t| t.strip_prefix("rotate(")?.split(',').next()?.trim().parse::<f64>().ok())
                .map_or(0, |a| a.round() as i32),
            content,
        });
        rest = &rest[close..];
    }
    (w, h, texts)
}

fn width(t: &Text) -> f64 {
    0.62 * t.size * t.content.chars().count() as f64
}

/// `(left, right, top, bottom)` of the text's box on the canvas.
fn extent(t: &Text) -> (f64, f64, f64, f64) {
    let w = width(t);
    let (along0, along1) = match t.anchor.as_str() {
        "middle" => (-w / 2.0, w / 2.0),
        "end" => (-w, 0.0),
        _ => (0.0, w),
    };
    let (across0, across1) = match t.dy.as_str() {
        "0.76em" => (0.0, t.size),
        "-0.5ex" => (-t.size, 0.0),
        _ => (-0.5 * t.size, 0.5 * t.size),
    };
    match t.rotation {
        // the text runs upwards from (x, y); its own "down" is +x
        270 | -90 => (t.x + across0, t.x + across1, t.y - along1, t.y - along0),
        // downwards; its "down" is −x
        90 => (t.x - across1, t.x - across0, t.y + along0, t.y + along1),
        _ => (t.x + along0, t.x + along1, t.y + across0, t.y + across1),
    }
}

fn is_number(s: &str) -> bool {
    !s.is_empty() && s.replace('−', "-").parse::<f64>().is_ok()
}

/// Split positions sorted ascending into runs where the gap grows past 2.5× the typical one
/// (one axis of one panel each).
fn clusters(mut items: Vec<(f64, Text)>) -> Vec<Vec<Text>> {
    items.sort_by(|a, b| a.0.total_cmp(&b.0));
    let gaps: Vec<f64> = items.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let mut sorted = gaps.clone();
    sorted.sort_by(f64::total_cmp);
    let typical = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let mut out: Vec<Vec<Text>> = Vec::new();
    for (k, (_, t)) in items.into_iter().enumerate() {
        if k == 0 || gaps[k - 1] > 2.5 * typical + 1.0 {
            out.push(Vec::new());
        }
        out.last_mut().unwrap().push(t);
    }
    out
}

/// Every defect of one figure, as lines naming it.
fn problems(name: &str, svg: &str) -> Vec<String> {
    let (w, h, texts) = parse(svg);
    let mut out = Vec::new();
    for t in &texts {
        let (l, r, top, bottom) = extent(t);
        if l < -1.0 || r > w + 1.0 || top < -1.0 || bottom > h + 1.0 {
            out.push(format!(
                "{name}: text {:?} leaves the {w}×{h} canvas ({l:.0}…{r:.0} × {top:.0}…{bottom:.0})",
                t.content
            ));
        }
    }
    // x-axis ticks: numbers centred under the axis (same y); y-axis ticks: numbers right-aligned
    // at the axis (same x). A y tick belongs to the panel whose x-tick row is the first below
    // it, an x tick to the panel whose y-tick column is the last left of it.
    let numbers: Vec<&Text> = texts
        .iter()
        .filter(|t| t.rotation == 0 && is_number(&t.content))
        .collect();
    let is_x = |t: &Text| t.anchor == "middle" && t.dy == "0.76em";
    let is_y = |t: &Text| t.anchor == "end" && t.dy == "0.5ex";
    let mut row_ys: Vec<f64> = numbers.iter().filter(|t| is_x(t)).map(|t| t.y).collect();
    let mut col_xs: Vec<f64> = numbers.iter().filter(|t| is_y(t)).map(|t| t.x).collect();
    row_ys.sort_by(f64::total_cmp);
    row_ys.dedup();
    col_xs.sort_by(f64::total_cmp);
    col_xs.dedup();
    let mut rows: BTreeMap<(i64, i64), Vec<(f64, Text)>> = BTreeMap::new();
    let mut cols: BTreeMap<(i64, i64), Vec<(f64, Text)>> = BTreeMap::new();
    for t in numbers {
        if is_x(t) {
            let panel = col_xs.iter().rev().find(|&&x| x < t.x).copied().unwrap_or(-1.0);
            rows.entry((t.y.round() as i64, panel.round() as i64))
                .or_default()
                .push((t.x, t.clone()));
        } else if is_y(t) {
            let panel = row_ys.iter().find(|&&y| y > t.y).copied().unwrap_or(-1.0);
            cols.entry((t.x.round() as i64, panel.round() as i64))
                .or_default()
                .push((t.y, t.clone()));
        }
    }
    for (axis, groups) in [("x", rows), ("y", cols)] {
        for group in groups.into_values() {
            for ticks in clusters(group) {
                let mut seen = BTreeMap::new();
                for t in &ticks {
                    if let Some(prev) = seen.insert(t.content.clone(), t) {
                        out.push(format!(
                            "{name}: {axis} tick label {:?} twice (at {:.0},{:.0} and {:.0},{:.0})",
                            t.content, prev.x, prev.y, t.x, t.y
                        ));
                    }
                }
                if axis == "x" {
                    for pair in ticks.windows(2) {
                        let room = (pair[1].x - pair[0].x).abs();
                        if room < 0.5 * (width(&pair[0]) + width(&pair[1])) {
                            out.push(format!(
                                "{name}: x tick labels {:?} and {:?} overlap",
                                pair[0].content, pair[1].content
                            ));
                        }
                    }
                }
            }
        }
    }
    out
}

fn run(dir: &Path, args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn svgs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    v.sort();
    v
}

#[test]
fn every_figure_kind_is_readable() {
    let dir = std::env::temp_dir().join(format!("substep-figure-checks-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let ex = |f: &str| examples.join(f).to_str().unwrap().to_string();
    let fmt = ["--plot-format", "svg"];
    let commands: Vec<Vec<String>> = vec![
        vec!["run".into(), "--out".into(), "run".into(), "--quiet".into()],
        vec![
            "run".into(),
            ex("shear_building_10.toml"),
            "--out".into(),
            "building".into(),
            "--quiet".into(),
        ],
        vec![
            "run".into(),
            ex("servo_physical.toml"),
            "--out".into(),
            "servo".into(),
            "--quiet".into(),
        ],
        vec![
            "vst".into(),
            "--quick".into(),
            "--out".into(),
            "vst".into(),
            "--quiet".into(),
        ],
        vec![
            "benchmark".into(),
            "rths".into(),
            "--case".into(),
            "1".into(),
            "--out".into(),
            "benchmark".into(),
        ],
        vec!["analyze".into(), "stability".into(), "--out".into(), "stability".into()],
        vec!["analyze".into(), "accuracy".into(), "--out".into(), "accuracy".into()],
        vec![
            "study".into(),
            ex("studies/substeps_delay.toml"),
            "--out".into(),
            "study".into(),
            "--quiet".into(),
        ],
    ];
    let mut all = Vec::new();
    let mut kinds = std::collections::BTreeSet::new();
    for c in &commands {
        let mut args: Vec<&str> = c.iter().map(String::as_str).collect();
        args.extend(fmt);
        run(&dir, &args);
        let out = &c[c.iter().position(|a| a == "--out").unwrap() + 1];
        let files = svgs(&dir.join(out));
        assert!(!files.is_empty(), "{args:?} drew nothing");
        for f in files {
            let svg = std::fs::read_to_string(&f).unwrap();
            let name = format!("{out}/{}", f.file_name().unwrap().to_string_lossy());
            kinds.insert(name.clone());
            all.extend(problems(&name, &svg));
            // Axis titles (rotated y titles and the x titles under the axes) name a unit.
            let (_, _, texts) = parse(&svg);
            for t in texts.iter().filter(|t| t.rotation != 0 || t.dy == "-0.5ex") {
                let unitless = ["storey", "run", "Ω", "ζ", "k_sub", "r = ω / ω", "Ω = ω Δt", "η"];
                if !t.content.contains('[') && !unitless.iter().any(|u| t.content.contains(u)) {
                    all.push(format!("{name}: axis title {:?} has no [unit]", t.content));
                }
            }
        }
    }
    println!("{} figures checked: {kinds:?}", kinds.len());
    assert!(kinds.len() >= 35, "{} figures", kinds.len());
    assert!(all.is_empty(), "{} problems:\n{}", all.len(), all.join("\n"));
    std::fs::remove_dir_all(&dir).ok();
}

/// The checker finds each defect on hand-written SVG (so the test above cannot pass by
/// finding nothing).
#[test]
fn the_checker_reports_each_defect() {
    let svg = |body: &str| format!("<svg width=\"200\" height=\"100\" viewBox=\"0 0 200 100\">\n{body}\n</svg>");
    let tick = |x: f64, y: f64, s: &str| {
        format!("<text x=\"{x}\" y=\"{y}\" dy=\"0.76em\" text-anchor=\"middle\" font-size=\"11\">\n{s}\n</text>")
    };
    let ok = svg(&[
        tick(40.0, 80.0, "7.25"),
        tick(80.0, 80.0, "7.30"),
        tick(120.0, 80.0, "7.35"),
    ]
    .join("\n"));
    assert!(problems("ok", &ok).is_empty(), "{:?}", problems("ok", &ok));
    let dup = svg(&[
        tick(40.0, 80.0, "7.3"),
        tick(80.0, 80.0, "7.3"),
        tick(120.0, 80.0, "7.5"),
    ]
    .join("\n"));
    let p = problems("dup", &dup);
    assert!(p.iter().any(|l| l.contains("x tick label \"7.3\" twice")), "{p:?}");
    let out = svg(&tick(195.0, 80.0, "a long label that sticks out"));
    let p = problems("out", &out);
    assert!(p.iter().any(|l| l.contains("leaves the 200×100 canvas")), "{p:?}");
    let crowded = svg(&[tick(40.0, 80.0, "1000000"), tick(50.0, 80.0, "2000000")].join("\n"));
    let p = problems("crowded", &crowded);
    assert!(p.iter().any(|l| l.contains("overlap")), "{p:?}");
    let rotated = svg(
        "<text x=\"10\" y=\"50\" dy=\"0.76em\" text-anchor=\"middle\" font-size=\"13\" transform=\"rotate(270, 10, 50)\">\nE_K + E_S + E_D − E_I − E_C [J]\n</text>",
    );
    let p = problems("rotated", &rotated);
    assert!(p.iter().any(|l| l.contains("leaves")), "{p:?}");
}
