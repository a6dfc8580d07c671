//! Figures with plotters, for every front end (the CLI's commands, Python's runs): PNG (drawn at
//! twice the size and averaged down, so lines and text are anti-aliased), SVG (plotters' SVG
//! backend) or PDF (the SVG converted by svg2pdf, cargo feature `pdf`), all with the bundled
//! DejaVu Sans, so no system fonts are needed.
//!
//! A [`Figure`] is a title over one or more [`Panel`]s stacked vertically (or in columns); each
//! panel has its own axes and its legend to the right of the data. [`line_chart`] and
//! [`rho_heatmap`] are the one-panel shortcuts. The caller passes the output format
//! ([`PlotFormat`]) to every drawing function; the functions replace the extension of
//! the path they are given and return the path actually written ([`output_path`]).
//! The heat map, with its colour scale and contour, is in `heatmap.rs`.

use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::Once;

mod heatmap;

pub use heatmap::rho_heatmap;

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
const COLORS: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(60, 60, 60),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(0, 0, 128),
    RGBColor(128, 128, 0),
];
/// Width reserved right of a panel for its legend [px at scale 1]: the longest label at about
/// 0.6 em per character of the 14 px legend font, plus the line sample; 120 to 380 px.
fn legend_width(p: &Panel) -> u32 {
    let chars = p.curves.iter().map(|c| c.label.chars().count()).max().unwrap_or(0);
    (50.0 + 8.6 * chars as f64).clamp(120.0, 380.0) as u32
}

/// Output format of a figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlotFormat {
    #[default]
    Png,
    Svg,
    Pdf,
}

impl PlotFormat {
    pub fn extension(self) -> &'static str {
        match self {
            PlotFormat::Png => "png",
            PlotFormat::Svg => "svg",
            PlotFormat::Pdf => "pdf",
        }
    }
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "png" => Some(PlotFormat::Png),
            "svg" => Some(PlotFormat::Svg),
            "pdf" => Some(PlotFormat::Pdf),
            _ => None,
        }
    }
}

/// How to get a build that writes PDF figures (the one-line refusal without it).
pub const PDF_HINT: &str = "this build of substep has no PDF figures (they pull in a font and SVG stack that \
     doubles the build time): build with `--features pdf` (cargo install --path crates/substep-cli --features pdf), \
     or use svg, which is vector too";

/// Refuse a format this build cannot draw, before any work: `what` names the option or key.
pub fn check_format(f: PlotFormat, what: &str) -> Result<()> {
    if f == PlotFormat::Pdf && !cfg!(feature = "pdf") {
        return Err(Error::invalid(what, format!("format `pdf`: {PDF_HINT}")));
    }
    Ok(())
}

/// `path` with the extension of `format`.
pub fn output_path(path: &Path, format: PlotFormat) -> PathBuf {
    path.with_extension(format.extension())
}

fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut result = Ok(());
    ONCE.call_once(|| {
        result = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .map_err(|_| Error::numerical("figure", "the bundled font DejaVuSans.ttf cannot be loaded"));
    });
    result
}

/// One curve of a chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
}

/// One set of axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub x_label: String,
    pub y_label: String,
    pub curves: Vec<Curve>,
    /// Logarithmic x axis (values must be > 0).
    pub log_x: bool,
    /// Draw a marker at every point.
    pub markers: bool,
    /// Share of the figure's height (relative to the other panels; 1 by default).
    pub height: f64,
    /// Only this x interval (a zoom window).
    pub x_window: Option<(f64, f64)>,
    /// Shade this x interval (where a zoom panel looks).
    pub highlight: Option<(f64, f64)>,
    /// The y axis counts things (storeys, runs): ticks only at whole numbers.
    pub integer_y: bool,
    /// The same for the x axis (sub-steps, seeds).
    pub integer_x: bool,
}

impl Panel {
    pub fn new(x_label: &str, y_label: &str) -> Self {
        Self {
            x_label: x_label.into(),
            y_label: y_label.into(),
            curves: Vec::new(),
            log_x: false,
            markers: false,
            height: 1.0,
            x_window: None,
            highlight: None,
            integer_y: false,
            integer_x: false,
        }
    }
    /// Whole-number x ticks when `on` (a parameter that only takes integers).
    pub fn integer_axis_x(mut self, on: bool) -> Self {
        self.integer_x = on;
        self
    }
    pub fn integer_y(mut self) -> Self {
        self.integer_y = true;
        self
    }
    pub fn curves(mut self, c: Vec<Curve>) -> Self {
        self.curves = c;
        self
    }
    pub fn log_x(mut self) -> Self {
        self.log_x = true;
        self
    }
    pub fn markers(mut self) -> Self {
        self.markers = true;
        self
    }
    pub fn height(mut self, h: f64) -> Self {
        self.height = h;
        self
    }
    pub fn window(mut self, lo: f64, hi: f64) -> Self {
        self.x_window = Some((lo, hi));
        self
    }
    pub fn highlight(mut self, lo: f64, hi: f64) -> Self {
        self.highlight = Some((lo, hi));
        self
    }
}

/// A titled set of panels.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    pub title: String,
    pub panels: Vec<Panel>,
    /// Panels per row (1: stacked).
    pub columns: usize,
    /// Size at scale 1 \[px\]; the height grows with the panels unless set.
    pub size: Option<(u32, u32)>,
}

impl Figure {
    pub fn new(title: &str) -> Self {
        Self {
            title: title.into(),
            panels: Vec::new(),
            columns: 1,
            size: None,
        }
    }
    pub fn panel(mut self, p: Panel) -> Self {
        self.panels.push(p);
        self
    }
    pub fn columns(mut self, c: usize) -> Self {
        self.columns = c.max(1);
        self
    }
    pub fn size(&self) -> (u32, u32) {
        self.size.unwrap_or_else(|| {
            if self.columns > 1 {
                return (1100, 560);
            }
            let h: f64 = self.panels.iter().map(|p| p.height).sum();
            (1100, (60.0 + 500.0 * h.max(0.5)).round() as u32)
        })
    }
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-300 {
        let pad = if lo.abs() > 0.0 { lo.abs() * 0.1 } else { 1.0 };
        return (lo - pad, hi + pad);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// How one axis writes its ticks: the values divided by `factor` (an SI prefix, see
/// [`engineering_unit`]) with enough digits that neighbouring ticks differ.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TickFormat {
    factor: f64,
    /// Decimals of fixed-point labels, or `None` for exponent notation with `mantissa` digits.
    decimals: Option<usize>,
    mantissa: usize,
    /// Only whole numbers get a label.
    integer: bool,
}

/// Tick spacing plotters uses for an axis of this span (at most ~10 labels, 1-2-5 steps),
/// estimated from above so that labels never need more digits than this gives.
fn tick_step(span: f64) -> f64 {
    let raw = span / 12.0;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&st| st >= raw)
        .unwrap_or(10.0 * p)
}

impl TickFormat {
    /// For an axis from `lo` to `hi` (already divided by `factor`).
    fn new(lo: f64, hi: f64, factor: f64, integer: bool) -> Self {
        let magnitude = lo.abs().max(hi.abs());
        let step = tick_step((hi - lo).abs().max(magnitude * 1e-12).max(1e-300));
        let (decimals, mantissa) = if (1e-4..1e5).contains(&magnitude) {
            (Some((-step.log10().floor()).clamp(0.0, 8.0) as usize), 0)
        } else {
            (
                None,
                (magnitude.log10().floor() - step.log10().floor()).clamp(1.0, 6.0) as usize,
            )
        };
        Self {
            factor,
            decimals,
            mantissa,
            integer,
        }
    }

    fn label(&self, v: f64) -> String {
        let v = v / self.factor;
        if self.integer {
            return if (v - v.round()).abs() < 1e-6 {
                format!("{}", v.round() as i64)
            } else {
                String::new()
            };
        }
        let step_zero = match self.decimals {
            Some(d) => 0.5 * 10f64.powi(-(d as i32)),
            None => 0.0,
        };
        if v == 0.0 || v.abs() < step_zero * 1e-6 {
            return "0".into();
        }
        match self.decimals {
            Some(d) => {
                let t = format!("{v:.d$}");
                // "-0.00" from a value that rounds to zero
                if t.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
                    "0".into()
                } else {
                    t
                }
            }
            None => format!("{v:.*e}", self.mantissa),
        }
    }
}

/// An SI prefix for the unit in brackets at the end of `label` (`"force [N]"`) so that the
/// axis' largest value `max_abs` reads between 1 and 1000: `("force [kN]", 1e3)`. Units that
/// take prefixes here: lengths (down to nm; never km), times (down to µs), forces, energies, powers, pressures,
/// stiffnesses and damping coefficients. Any other label is returned unchanged with factor 1.
pub fn engineering_unit(label: &str, max_abs: f64) -> (String, f64) {
    let unchanged = (label.to_string(), 1.0);
    let Some(open) = label.rfind('[') else {
        return unchanged;
    };
    let Some(unit) = label[open + 1..].strip_suffix(']') else {
        return unchanged;
    };
    let (lowest, highest) = match unit {
        "m" => (-9, 0),
        "s" => (-6, 0),
        "N" | "J" | "W" | "Pa" | "N/m" | "N·s/m" | "N s/m" | "N·m" => (-3, 9),
        _ => return unchanged,
    };
    if !(max_abs.is_finite() && max_abs > 0.0) {
        return unchanged;
    }
    let k = ((max_abs.log10() / 3.0).floor() as i32 * 3).clamp(lowest, highest);
    let prefix = match k {
        -9 => "n",
        -6 => "µ",
        -3 => "m",
        3 => "k",
        6 => "M",
        9 => "G",
        _ => return unchanged,
    };
    (format!("{}[{prefix}{unit}]", &label[..open]), 10f64.powi(k))
}

/// A log-axis tick (the axis holds `log10 x`).
fn log_tick(v: f64) -> String {
    let x = 10f64.powf(v);
    if x >= 100.0 {
        format!("{x:.0}")
    } else if x >= 1.0 {
        format!("{x:.2}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string()
    } else {
        let digits = (1.0 - x.log10().floor()).clamp(1.0, 6.0) as usize;
        format!("{x:.digits$}")
    }
}

type DrawResult = std::result::Result<(), String>;

fn e<E: std::fmt::Debug>(err: E) -> String {
    format!("{err:?}")
}

/// Draw `fig` on `root` with every length multiplied by `s`.
fn draw_figure<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure, s: f64) -> DrawResult {
    let px = |v: f64| (v * s).round() as i32;
    root.fill(&WHITE).map_err(e)?;
    let (w, h) = root.dim_in_pixel();
    let title_h = px(44.0) as u32;
    let (top, body) = root.split_vertically(title_h);
    top.draw(&Text::new(
        fig.title.clone(),
        ((w / 2) as i32, px(12.0)),
        ("sans-serif", 22.0 * s)
            .into_font()
            .color(&BLACK)
            .pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Center,
                plotters::style::text_anchor::VPos::Top,
            )),
    ))
    .map_err(e)?;
    let areas: Vec<DrawingArea<DB, Shift>> = if fig.columns > 1 {
        let n = fig.panels.len().max(1);
        body.split_evenly((1, n))
    } else {
        let total: f64 = fig.panels.iter().map(|p| p.height).sum::<f64>().max(1e-9);
        let mut rest = body;
        let mut out = Vec::new();
        let body_h = (h - title_h) as f64;
        for (i, p) in fig.panels.iter().enumerate() {
            if i + 1 == fig.panels.len() {
                out.push(rest);
                break;
            }
            let (a, b) = rest.split_vertically((body_h * p.height / total).round() as u32);
            out.push(a);
            rest = b;
        }
        out
    };
    for (p, area) in fig.panels.iter().zip(&areas) {
        draw_panel(area, p, s, fig.columns == 1)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel, s: f64, legend_right: bool) -> DrawResult {
    let px = |v: f64| (v * s).round() as u32;
    let tx = |x: f64| if p.log_x { x.log10() } else { x };
    let in_window = |x: f64| p.x_window.is_none_or(|(lo, hi)| x >= lo && x <= hi);
    let (x0, x1) = match p.x_window {
        Some((lo, hi)) => (tx(lo), tx(hi)),
        None => range(p.curves.iter().flat_map(|c| c.x.iter().copied().map(tx))),
    };
    let (y0, y1) = range(
        p.curves
            .iter()
            .flat_map(|c| c.x.iter().zip(&c.y).filter(|(x, _)| in_window(**x)).map(|(_, y)| *y)),
    );
    let labelled = p.curves.iter().any(|c| !c.label.is_empty());
    let (plot_area, legend_area) = if labelled && legend_right {
        let (w, _) = area.dim_in_pixel();
        let (a, b) = area.split_horizontally(w.saturating_sub(px(legend_width(p) as f64)));
        (a, Some(b))
    } else {
        (area.clone(), None)
    };
    // Engineering units (kN, mm) and ticks with as many digits as their spacing needs.
    let (x_label, x_factor) = if p.log_x {
        (p.x_label.clone(), 1.0)
    } else {
        engineering_unit(&p.x_label, x0.abs().max(x1.abs()))
    };
    let (y_label, y_factor) = engineering_unit(&p.y_label, y0.abs().max(y1.abs()));
    let x_ticks = TickFormat::new(x0 / x_factor, x1 / x_factor, x_factor, p.integer_x);
    let y_ticks = TickFormat::new(y0 / y_factor, y1 / y_factor, y_factor, p.integer_y);
    // Room for the longest y tick label (about 0.6 em per character) and the axis title.
    let y_chars = [y0, y1, 0.5 * (y0 + y1)]
        .iter()
        .map(|&v| y_ticks.label(v).chars().count())
        .max()
        .unwrap_or(4);
    let y_area = (30.0 + 8.6 * y_chars as f64).clamp(56.0, 140.0);
    let mut chart = ChartBuilder::on(&plot_area)
        .margin(px(10.0))
        .x_label_area_size(px(48.0))
        .y_label_area_size(px(y_area))
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let log_x = p.log_x;
    let x_fmt = move |v: &f64| if log_x { log_tick(*v) } else { x_ticks.label(*v) };
    chart
        .configure_mesh()
        .x_desc(x_label.as_str())
        .y_desc(y_label.as_str())
        .label_style(("sans-serif", 14.0 * s))
        .axis_desc_style(("sans-serif", 16.0 * s))
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&|v| y_ticks.label(*v))
        // panels side by side are half as wide: half as many x labels
        .x_labels(if legend_right { 10 } else { 5 })
        .bold_line_style(RGBColor(215, 215, 215).stroke_width(px(1.0)))
        .light_line_style(RGBColor(242, 242, 242).stroke_width(px(1.0)))
        .max_light_lines(if p.height < 0.8 { 1 } else { 4 })
        .axis_style(RGBColor(90, 90, 90).stroke_width(px(1.0)))
        .draw()
        .map_err(e)?;
    if let Some((lo, hi)) = p.highlight {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(tx(lo), y0), (tx(hi), y1)],
                RGBColor(255, 200, 60).mix(0.25).filled(),
            )))
            .map_err(e)?;
    }
    let width = px(1.25).max(1);
    for (k, c) in p.curves.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        // Finite runs only: a NaN breaks the line instead of joining across it; values are
        // clamped to the axes so that nothing is drawn outside them.
        let mut run: Vec<(f64, f64)> = Vec::new();
        let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
        for (&x, &y) in c.x.iter().zip(&c.y) {
            let ok = x.is_finite() && y.is_finite() && (!p.log_x || x > 0.0) && in_window(x);
            if ok {
                run.push((tx(x), y.clamp(y0, y1)));
            } else if !run.is_empty() {
                runs.push(std::mem::take(&mut run));
            }
        }
        if !run.is_empty() {
            runs.push(run);
        }
        for r in &runs {
            if r.len() == 1 || p.markers {
                chart
                    .draw_series(r.iter().map(|&q| Circle::new(q, px(3.0), color.filled())))
                    .map_err(e)?;
            }
            if r.len() > 1 && s > 1.0 {
                // Bitmap (supersampled): plotters joins a thick polyline with unlimited miters,
                // which shoot spikes out of the axes at sharp reversals of noisy data; separate
                // segments have no joins.
                chart
                    .draw_series(
                        r.windows(2)
                            .map(|w| PathElement::new(vec![w[0], w[1]], color.stroke_width(width))),
                    )
                    .map_err(e)?;
            } else if r.len() > 1 {
                chart
                    .draw_series(LineSeries::new(r.iter().copied(), color.stroke_width(width)))
                    .map_err(e)?;
            }
        }
    }
    if let Some(legend) = legend_area {
        let font = ("sans-serif", 14.0 * s).into_font().color(&BLACK);
        let line_h = px(22.0) as i32;
        let top = px(30.0) as i32;
        for (k, c) in p.curves.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            let y = top + k as i32 * line_h;
            legend
                .draw(&PathElement::new(
                    vec![(px(6.0) as i32, y), (px(30.0) as i32, y)],
                    color.stroke_width(px(2.0)),
                ))
                .map_err(e)?;
            legend
                .draw(&Text::new(
                    c.label.clone(),
                    (px(36.0) as i32, y - px(8.0) as i32),
                    font.clone(),
                ))
                .map_err(e)?;
        }
    } else if labelled && p.curves.len() > 1 {
        // Side-by-side panels: a legend in the upper corner of the plot area.
        for (k, c) in p.curves.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            let _ = chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), u32>>())
                .map(|a| {
                    a.label(c.label.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(2)));
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(160, 160, 160))
            .label_font(("sans-serif", 14.0 * s))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

/// Render with `draw` at `size` in `format` to `path` (extension replaced); returns the
/// written path.
fn render(
    path: &Path,
    format: PlotFormat,
    size: (u32, u32),
    draw: impl Fn(&dyn Fn(f64) -> f64, RenderTarget) -> DrawResult,
) -> Result<PathBuf> {
    register_font()?;
    let out = output_path(path, format);
    let fail = |m: String| Error::file(out.display().to_string(), format!("cannot draw: {m}"));
    let cannot_write = |e: std::io::Error| Error::write(&out, e);
    match format {
        PlotFormat::Png => {
            // Twice the size, then a 2×2 box filter: anti-aliased lines and text.
            let (w, h) = (size.0 * 2, size.1 * 2);
            let mut buf = vec![255u8; (w * h * 3) as usize];
            draw(&|v| v * 2.0, RenderTarget::Bitmap(&mut buf, (w, h))).map_err(fail)?;
            let mut small = vec![0u8; (size.0 * size.1 * 3) as usize];
            for y in 0..size.1 as usize {
                for x in 0..size.0 as usize {
                    for c in 0..3 {
                        let at = |dx: usize, dy: usize| buf[((2 * y + dy) * w as usize + 2 * x + dx) * 3 + c] as u32;
                        small[(y * size.0 as usize + x) * 3 + c] =
                            ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8;
                    }
                }
            }
            // Written to a temporary file and renamed: a killed run never leaves half a PNG.
            crate::atomic_file::replace_atomic(&out, |tmp| {
                image::save_buffer_with_format(
                    tmp,
                    &small,
                    size.0,
                    size.1,
                    image::ColorType::Rgb8,
                    image::ImageFormat::Png,
                )
                .map_err(std::io::Error::other)
            })
            .map_err(cannot_write)?;
        }
        PlotFormat::Svg | PlotFormat::Pdf => {
            let mut svg = String::new();
            draw(&|v| v, RenderTarget::Svg(&mut svg, size)).map_err(fail)?;
            let bytes = if format == PlotFormat::Svg {
                svg.into_bytes()
            } else {
                svg_to_pdf(&svg).map_err(fail)?
            };
            crate::atomic_file::write_atomic(&out, &bytes).map_err(cannot_write)?;
        }
    }
    Ok(out)
}

/// Where [`render`] draws.
enum RenderTarget<'a> {
    Bitmap(&'a mut [u8], (u32, u32)),
    Svg(&'a mut String, (u32, u32)),
}

/// Without the `pdf` feature: the refusal ([`check_format`] refuses earlier).
#[cfg(not(feature = "pdf"))]
fn svg_to_pdf(_svg: &str) -> std::result::Result<Vec<u8>, String> {
    Err(format!("format `pdf`: {PDF_HINT}"))
}

/// SVG text → PDF bytes, with the bundled font for the text.
#[cfg(feature = "pdf")]
fn svg_to_pdf(svg: &str) -> std::result::Result<Vec<u8>, String> {
    use svg2pdf::usvg;
    let mut options = usvg::Options::default();
    let db = options.fontdb_mut();
    db.load_font_data(FONT.to_vec());
    // plotters writes the generic family `sans-serif`: resolve it to the bundled font.
    db.set_sans_serif_family("DejaVu Sans");
    options.font_family = "DejaVu Sans".into();
    let tree = usvg::Tree::from_str(svg, &options).map_err(|e| format!("SVG: {e}"))?;
    svg2pdf::to_pdf(
        &tree,
        svg2pdf::ConversionOptions::default(),
        svg2pdf::PageOptions::default(),
    )
    .map_err(|e| format!("PDF: {e:?}"))
}

/// Draw `fig` to `path` (extension replaced by `format`'s); returns the written path.
pub fn figure(path: &Path, fig: &Figure, format: PlotFormat) -> Result<PathBuf> {
    render(path, format, fig.size(), |s, target| {
        let scale = s(1.0);
        match target {
            RenderTarget::Bitmap(buf, size) => {
                let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
                draw_figure(&root, fig, scale)?;
                root.present().map_err(e)
            }
            RenderTarget::Svg(buf, size) => {
                let root = SVGBackend::with_string(buf, size).into_drawing_area();
                draw_figure(&root, fig, scale)?;
                root.present().map_err(e)
            }
        }
    })
}

/// Draw `curves` into one panel at `path` (1100×560 px; the extension follows `format`, see
/// [`output_path`]); returns the written path.
pub fn line_chart(
    path: &Path,
    format: PlotFormat,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
) -> Result<PathBuf> {
    let fig = Figure {
        size: Some((1100, 560)),
        ..Figure::new(title).panel(Panel::new(x_label, y_label).curves(curves.to_vec()))
    };
    figure(path, &fig, format)
}

#[cfg(test)]
mod tests {
    use super::heatmap::contour_segments;
    use super::*;

    #[test]
    fn ticks_and_ranges() {
        let t = |lo: f64, hi: f64, v: f64| TickFormat::new(lo, hi, 1.0, false).label(v);
        assert_eq!(t(-1.0, 1.0, 0.0), "0");
        assert_eq!(t(-0.1, 0.1, -1e-17), "0");
        assert_eq!(t(-1.0, 1.0, 0.5), "0.5");
        assert_eq!(t(0.0, 750.0, 400.0), "400");
        assert_eq!(t(0.0, 3.0e-4, 2.0e-4), "0.00020");
        assert_eq!(t(0.0, 3.0e-5, 2.0e-5), "2.0e-5");
        // A zoom window of 0.6 s around t = 7.5 s: ticks every 0.05 s must read apart (the
        // old magnitude-based format wrote 7.3, 7.3, 7.5).
        let labels: Vec<String> = (0..12).map(|k| t(7.2, 7.8, 7.25 + 0.05 * k as f64)).collect();
        let unique: std::collections::BTreeSet<&String> = labels.iter().collect();
        assert_eq!(unique.len(), labels.len(), "{labels:?}");
        assert_eq!(labels[..3], ["7.25", "7.30", "7.35"]);
        // exponent notation with the digits the spacing needs
        assert_eq!(t(7.5e5, 8.1e5, 7.55e5), "7.55e5");
        // whole numbers only on a counting axis
        let storey = TickFormat::new(0.8, 3.2, 1.0, true);
        assert_eq!((storey.label(2.0), storey.label(2.5)), ("2".to_string(), String::new()));
        // engineering units
        assert_eq!(engineering_unit("force [N]", 5.0e5), ("force [kN]".to_string(), 1e3));
        assert_eq!(engineering_unit("force [N]", 2.5e6), ("force [MN]".to_string(), 1e6));
        assert_eq!(engineering_unit("u [m]", 0.012), ("u [mm]".to_string(), 1e-3));
        assert_eq!(engineering_unit("u [m]", 3.0e-6), ("u [µm]".to_string(), 1e-6));
        assert_eq!(engineering_unit("u [m]", 5.0e3), ("u [m]".to_string(), 1.0));
        assert_eq!(engineering_unit("delay [s]", 0.01), ("delay [ms]".to_string(), 1e-3));
        assert_eq!(engineering_unit("t [s]", 20.0), ("t [s]".to_string(), 1.0));
        assert_eq!(engineering_unit("E [J]", 12.0), ("E [J]".to_string(), 1.0));
        assert_eq!(engineering_unit("a [m/s²]", 1e4), ("a [m/s²]".to_string(), 1.0));
        assert_eq!(engineering_unit("V [kN]", 1e4), ("V [kN]".to_string(), 1.0));
        let f = TickFormat::new(0.0, 500.0, 1e3, false);
        assert_eq!(f.label(2.5e5), "250");
        assert_eq!(log_tick(0.0), "1");
        assert_eq!(log_tick(-1.0), "0.10");
        assert_eq!(range([0.0, 0.0].into_iter()), (-1.0, 1.0));
        let (lo, hi) = range([1.0, 3.0].into_iter());
        assert!(lo < 1.0 && hi > 3.0);
    }

    /// PNG width and height from the IHDR chunk.
    fn png_size(bytes: &[u8]) -> (u32, u32) {
        assert_eq!(&bytes[1..4], b"PNG");
        let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        (be(16), be(20))
    }

    /// Pixels within a small distance of `c` in a decoded PNG.
    fn pixels_near(path: &Path, c: RGBColor) -> usize {
        let img = image::open(path).unwrap().to_rgb8();
        img.pixels()
            .filter(|p| {
                let d = |a: u8, b: u8| (a as i32 - b as i32).abs();
                d(p[0], c.0) + d(p[1], c.1) + d(p[2], c.2) < 60
            })
            .count()
    }

    #[test]
    fn every_figure_kind_renders_in_every_format() {
        let dir = std::env::temp_dir().join(format!("substep-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let t: Vec<f64> = (0..500).map(|i| i as f64 * 0.01).collect();
        let sine = |f: f64| t.iter().map(|&x| (f * x).sin()).collect::<Vec<_>>();
        let mut with_gap = sine(3.0);
        with_gap[100] = f64::NAN;
        let curves = vec![
            Curve {
                label: "a".into(),
                x: t.clone(),
                y: sine(2.0),
            },
            Curve {
                label: "b".into(),
                x: t.clone(),
                y: with_gap,
            },
            Curve {
                label: "c".into(),
                x: t.clone(),
                y: sine(5.0),
            },
        ];
        let multi = Figure::new("three panels")
            .panel(Panel::new("t [s]", "u [m]").curves(curves.clone()).highlight(1.0, 2.0))
            .panel(Panel::new("t [s]", "e [m]").curves(curves[..1].to_vec()).height(0.4))
            .panel(
                Panel::new("t [s]", "u [m]")
                    .curves(curves.clone())
                    .window(1.0, 2.0)
                    .height(0.6),
            );
        let periods: Vec<f64> = (1..50).map(|i| 0.02 * i as f64).collect();
        let logf = Figure::new("log x").panel(
            Panel::new("T [s]", "S [m/s²]")
                .curves(vec![Curve {
                    label: "S".into(),
                    x: periods.clone(),
                    y: periods.iter().map(|p| 1.0 / p).collect(),
                }])
                .log_x()
                .markers(),
        );
        let cols = Figure::new("columns")
            .columns(2)
            .panel(Panel::new("x", "y").curves(curves.clone()))
            .panel(Panel::new("x", "y").curves(curves[..2].to_vec()));
        let xs: Vec<f64> = (0..30).map(|i| 0.1 * i as f64).collect();
        let ys: Vec<f64> = (0..20).map(|i| 0.01 * i as f64).collect();
        let rho: Vec<Vec<f64>> = ys
            .iter()
            .map(|y| xs.iter().map(|x| 0.95 + 0.04 * x - y).collect())
            .collect();
        let formats: &[PlotFormat] = if cfg!(feature = "pdf") {
            &[PlotFormat::Png, PlotFormat::Svg, PlotFormat::Pdf]
        } else {
            &[PlotFormat::Png, PlotFormat::Svg]
        };
        for &fmt in formats {
            let mut written = Vec::new();
            for (name, fig) in [("multi", &multi), ("log", &logf), ("cols", &cols)] {
                written.push((
                    figure(&dir.join(name), fig, fmt).unwrap(),
                    fig.size(),
                    fig.panels.iter().map(|p| p.curves.len()).max().unwrap(),
                ));
            }
            line_chart(&dir.join("line.png"), fmt, "one", "x", "y", &curves).unwrap();
            written.push((output_path(&dir.join("line.png"), fmt), (1100, 560), 3));
            rho_heatmap(&dir.join("map.png"), fmt, "ρ", "Ω", "ζ_s", &xs, &ys, &rho).unwrap();
            written.push((output_path(&dir.join("map.png"), fmt), (1000, 700), 0));
            for (path, size, series) in written {
                assert_eq!(path.extension().unwrap(), fmt.extension());
                let bytes = std::fs::read(&path).unwrap();
                assert!(bytes.len() > 2000, "{}: {} bytes", path.display(), bytes.len());
                match fmt {
                    PlotFormat::Png => {
                        assert_eq!(png_size(&bytes), size, "{}", path.display());
                        for (k, &c) in COLORS.iter().enumerate().take(series) {
                            assert!(pixels_near(&path, c) > 200, "{}: series {k} not drawn", path.display());
                        }
                    }
                    PlotFormat::Svg => {
                        let text = String::from_utf8(bytes).unwrap();
                        // usvg (with the pdf feature) parses it as an SVG renderer would
                        #[cfg(feature = "pdf")]
                        {
                            let tree = svg2pdf::usvg::Tree::from_str(&text, &svg2pdf::usvg::Options::default());
                            assert!(tree.is_ok(), "{}: {:?}", path.display(), tree.err());
                        }
                        assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
                        assert!(text.contains(&format!("width=\"{}\"", size.0)), "{}", path.display());
                        for (k, c) in COLORS.iter().enumerate().take(series) {
                            assert!(
                                text.contains(&format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)),
                                "{}: series {k}",
                                path.display()
                            );
                        }
                    }
                    PlotFormat::Pdf => {
                        assert!(bytes.starts_with(b"%PDF-"), "{}", path.display());
                        let tail = String::from_utf8_lossy(&bytes[bytes.len() - 64..]).to_string();
                        assert!(tail.contains("%%EOF"), "{}: {tail}", path.display());
                    }
                }
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn contour_of_a_plane_is_a_straight_line() {
        // ρ − 1 = x − 0.5 on a 3×3 grid: the contour is x = 0.5 in both rows of cells.
        let xs = [0.0, 0.4, 1.0];
        let ys = [0.0, 1.0, 2.0];
        let rho: Vec<Vec<f64>> = ys.iter().map(|_| xs.iter().map(|x| 0.5 + x).collect()).collect();
        let segs = contour_segments(&xs, &ys, &rho);
        assert_eq!(segs.len(), 2);
        for s in segs {
            for p in s {
                assert!((p.0 - 0.5).abs() < 1e-12, "{p:?}");
            }
        }
    }
}
