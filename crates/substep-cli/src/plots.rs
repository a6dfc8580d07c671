//! PNG line charts with plotters (bitmap backend, ab_glyph text with the bundled DejaVu Sans,
//! so no system fonts are needed).

use anyhow::{Context, Result, anyhow};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::Once;

const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(60, 60, 60),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
];

fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut result = Ok(());
    ONCE.call_once(|| {
        result = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .map_err(|_| anyhow!("the bundled font DejaVuSans.ttf cannot be loaded"));
    });
    result
}

/// One curve of a chart.
pub struct Curve {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
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

/// Tick labels: plain for moderate magnitudes, exponent notation otherwise.
fn tick(v: f64, scale: f64) -> String {
    if v.abs() <= 1e-9 * scale {
        "0".into()
    } else if (1e-2..1e5).contains(&scale) {
        let digits = (1.0 - scale.log10().floor()).clamp(0.0, 4.0) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.1e}")
    }
}

/// Draw `curves` into the PNG `path` (1000×560 px).
pub fn line_chart(path: &Path, title: &str, x_label: &str, y_label: &str, curves: &[Curve]) -> Result<()> {
    register_font()?;
    let draw = |path: &Path| -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let root = BitMapBackend::new(path, (1000, 560)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = range(curves.iter().flat_map(|c| c.x.iter().copied()));
        let (y0, y1) = range(curves.iter().flat_map(|c| c.y.iter().copied()));
        let (xs, ys) = (x0.abs().max(x1.abs()), y0.abs().max(y1.abs()));
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(84)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .x_label_formatter(&|v| tick(*v, xs))
            .y_label_formatter(&|v| tick(*v, ys))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        for (k, c) in curves.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    c.x.iter()
                        .copied()
                        .zip(c.y.iter().copied())
                        .filter(|(x, y)| x.is_finite() && y.is_finite()),
                    color.stroke_width(if curves.len() > 1 && k == 0 { 2 } else { 1 }),
                ))?
                .label(c.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(2)));
        }
        if curves.len() > 1 || curves.iter().any(|c| !c.label.is_empty()) {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(160, 160, 160))
                .label_font(("sans-serif", 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()?;
        }
        root.present()?;
        Ok(())
    };
    // Drawn to a temporary file and renamed: a killed run never leaves half a PNG.
    crate::output::replace_atomic(path, |tmp| draw(tmp).map_err(|e| std::io::Error::other(e.to_string())))
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("cannot draw {}", path.display()))
}

/// Colour of a spectral radius: white at `ρ = 1`, towards blue for `ρ < 1` and red for `ρ > 1`
/// (saturating at `|ln ρ| = 0.1`), grey for NaN.
fn rho_color(rho: f64) -> RGBColor {
    if !rho.is_finite() {
        return RGBColor(160, 160, 160);
    }
    let t = (rho.ln().abs() / 0.1).clamp(0.0, 1.0).sqrt();
    let mix = |a: u8, b: u8| (a as f64 + t * (b as f64 - a as f64)).round() as u8;
    if rho <= 1.0 {
        RGBColor(mix(255, 40), mix(255, 90), mix(255, 200))
    } else {
        RGBColor(mix(255, 200), mix(255, 30), mix(255, 30))
    }
}

/// A heat map of `ρ` over a rectangular grid (`rho[iy][ix]` at `(xs[ix], ys[iy])`) with the
/// `ρ = 1` contour (points where `ρ − 1` changes sign between grid neighbours, interpolated).
pub fn rho_heatmap(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    xs: &[f64],
    ys: &[f64],
    rho: &[Vec<f64>],
) -> Result<()> {
    register_font()?;
    let half = |v: &[f64], i: usize| -> (f64, f64) {
        let lo = if i == 0 {
            v[0] - (v.get(1).copied().unwrap_or(v[0] + 1.0) - v[0]) / 2.0
        } else {
            (v[i - 1] + v[i]) / 2.0
        };
        let hi = if i + 1 == v.len() {
            v[i] + (v[i] - v.get(i.wrapping_sub(1)).copied().unwrap_or(v[i] - 1.0)) / 2.0
        } else {
            (v[i] + v[i + 1]) / 2.0
        };
        (lo, hi)
    };
    let draw = |path: &Path| -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let root = BitMapBackend::new(path, (900, 700)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = (half(xs, 0).0, half(xs, xs.len() - 1).1);
        let (y0, y1) = (half(ys, 0).0, half(ys, ys.len() - 1).1);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()?;
        chart.draw_series(ys.iter().enumerate().flat_map(|(iy, _)| {
            xs.iter().enumerate().map(move |(ix, _)| {
                let (xa, xb) = half(xs, ix);
                let (ya, yb) = half(ys, iy);
                Rectangle::new([(xa, ya), (xb, yb)], rho_color(rho[iy][ix]).filled())
            })
        }))?;
        let mut contour = Vec::new();
        for iy in 0..ys.len() {
            for ix in 0..xs.len() {
                let r = rho[iy][ix] - 1.0;
                if ix + 1 < xs.len() {
                    let q = rho[iy][ix + 1] - 1.0;
                    if r.is_finite() && q.is_finite() && (r > 0.0) != (q > 0.0) {
                        contour.push((xs[ix] + r / (r - q) * (xs[ix + 1] - xs[ix]), ys[iy]));
                    }
                }
                if iy + 1 < ys.len() {
                    let q = rho[iy + 1][ix] - 1.0;
                    if r.is_finite() && q.is_finite() && (r > 0.0) != (q > 0.0) {
                        contour.push((xs[ix], ys[iy] + r / (r - q) * (ys[iy + 1] - ys[iy])));
                    }
                }
            }
        }
        chart
            .draw_series(contour.iter().map(|&p| Circle::new(p, 1, BLACK.filled())))?
            .label("ρ = 1")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .label_font(("sans-serif", 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
        Ok(())
    };
    // Drawn to a temporary file and renamed: a killed run never leaves half a PNG.
    crate::output::replace_atomic(path, |tmp| draw(tmp).map_err(|e| std::io::Error::other(e.to_string())))
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("cannot draw {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_and_ranges() {
        assert_eq!(tick(0.0, 1.0), "0");
        assert_eq!(tick(-1e-17, 0.1), "0");
        assert_eq!(tick(0.5, 1.0), "0.5");
        assert_eq!(tick(0.06, 0.07), "0.060");
        assert_eq!(tick(400.0, 750.0), "400");
        assert_eq!(tick(2.0e-4, 3.0e-4), "2.0e-4");
        assert_eq!(range([0.0, 0.0].into_iter()), (-1.0, 1.0));
        let (lo, hi) = range([1.0, 3.0].into_iter());
        assert!(lo < 1.0 && hi > 3.0);
    }
}
