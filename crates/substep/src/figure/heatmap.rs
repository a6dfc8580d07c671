//! The spectral-radius heat map ([`rho_heatmap`]): colour scale, the `ρ = 1` contour by marching
//! squares, the colour bar.

use super::*;

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

/// Segments of the `ρ = 1` contour by marching squares on the grid points.
pub(super) fn contour_segments(xs: &[f64], ys: &[f64], rho: &[Vec<f64>]) -> Vec<[(f64, f64); 2]> {
    let mut out = Vec::new();
    for iy in 0..ys.len().saturating_sub(1) {
        for ix in 0..xs.len().saturating_sub(1) {
            let corners = [
                (xs[ix], ys[iy], rho[iy][ix] - 1.0),
                (xs[ix + 1], ys[iy], rho[iy][ix + 1] - 1.0),
                (xs[ix + 1], ys[iy + 1], rho[iy + 1][ix + 1] - 1.0),
                (xs[ix], ys[iy + 1], rho[iy + 1][ix] - 1.0),
            ];
            if corners.iter().any(|c| !c.2.is_finite()) {
                continue;
            }
            let mut pts = Vec::new();
            for k in 0..4 {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                if (a.2 > 0.0) != (b.2 > 0.0) {
                    let f = a.2 / (a.2 - b.2);
                    pts.push((a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1)));
                }
            }
            if pts.len() >= 2 {
                out.push([pts[0], pts[1]]);
            }
            if pts.len() == 4 {
                out.push([pts[2], pts[3]]);
            }
        }
    }
    out
}

// The backend, the scale, three labels and the grid: a struct would only rename them.
#[allow(clippy::too_many_arguments)]
fn draw_heatmap<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: f64,
    title: &str,
    x_label: &str,
    y_label: &str,
    xs: &[f64],
    ys: &[f64],
    rho: &[Vec<f64>],
) -> DrawResult {
    let px = |v: f64| (v * s).round() as u32;
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
    root.fill(&WHITE).map_err(e)?;
    let (w, _) = root.dim_in_pixel();
    let (main, bar) = root.split_horizontally(w - px(160.0));
    let (x0, x1) = (half(xs, 0).0, half(xs, xs.len() - 1).1);
    let (y0, y1) = (half(ys, 0).0, half(ys, ys.len() - 1).1);
    let mut chart = ChartBuilder::on(&main)
        .caption(title, ("sans-serif", 20.0 * s))
        .margin(px(14.0))
        .x_label_area_size(px(48.0))
        .y_label_area_size(px(70.0))
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let x_ticks = super::TickFormat::new(x0, x1, 1.0, false);
    let y_ticks = super::TickFormat::new(y0, y1, 1.0, false);
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style(("sans-serif", 14.0 * s))
        .axis_desc_style(("sans-serif", 16.0 * s))
        .x_label_formatter(&|v| x_ticks.label(*v))
        .y_label_formatter(&|v| y_ticks.label(*v))
        .draw()
        .map_err(e)?;
    chart
        .draw_series(ys.iter().enumerate().flat_map(|(iy, _)| {
            xs.iter().enumerate().map(move |(ix, _)| {
                let (xa, xb) = half(xs, ix);
                let (ya, yb) = half(ys, iy);
                Rectangle::new([(xa, ya), (xb, yb)], rho_color(rho[iy][ix]).filled())
            })
        }))
        .map_err(e)?;
    for seg in contour_segments(xs, ys, rho) {
        chart
            .draw_series(std::iter::once(PathElement::new(
                seg.to_vec(),
                BLACK.stroke_width(px(2.0)),
            )))
            .map_err(e)?;
    }
    // Colour bar: ρ from e^{-0.1} to e^{0.1} (the colour scale saturates beyond), ρ = 1 marked.
    let (r_lo, r_hi) = ((-0.1f64).exp(), 0.1f64.exp());
    let mut cb = ChartBuilder::on(&bar)
        .margin_top(px(60.0))
        .margin_bottom(px(62.0))
        .margin_right(px(10.0))
        .y_label_area_size(px(0.0))
        .right_y_label_area_size(px(86.0))
        .build_cartesian_2d(0.0..1.0, r_lo..r_hi)
        .map_err(e)?
        .set_secondary_coord(0.0..1.0, r_lo..r_hi);
    cb.configure_secondary_axes()
        .y_desc("spectral radius ρ [–]")
        .label_style(("sans-serif", 13.0 * s))
        .axis_desc_style(("sans-serif", 15.0 * s))
        .y_labels(9)
        .y_label_formatter(&|v| format!("{v:.3}"))
        .draw()
        .map_err(e)?;
    let steps = 120;
    cb.draw_series((0..steps).map(|i| {
        let a = r_lo + (r_hi - r_lo) * i as f64 / steps as f64;
        let b = r_lo + (r_hi - r_lo) * (i + 1) as f64 / steps as f64;
        Rectangle::new([(0.0, a), (1.0, b)], rho_color(0.5 * (a + b)).filled())
    }))
    .map_err(e)?;
    cb.draw_series(std::iter::once(PathElement::new(
        vec![(0.0, 1.0), (1.0, 1.0)],
        BLACK.stroke_width(px(2.0)),
    )))
    .map_err(e)?;
    cb.draw_series(std::iter::once(Rectangle::new(
        [(0.0, r_lo), (1.0, r_hi)],
        BLACK.stroke_width(px(1.0)),
    )))
    .map_err(e)?;
    let (bw, bh) = bar.dim_in_pixel();
    bar.draw(&Text::new(
        "ρ = 1 (black line)".to_string(),
        (px(4.0) as i32, (bh - px(30.0)) as i32),
        ("sans-serif", 12.0 * s).into_font().color(&BLACK),
    ))
    .map_err(e)?;
    let _ = bw;
    Ok(())
}

/// A heat map of `ρ` over a rectangular grid (`rho[iy][ix]` at `(xs[ix], ys[iy])`) with a colour
/// bar and the `ρ = 1` contour (marching squares on the grid values, linear interpolation).
// The heat map's labels and grid, and the format: a struct would only rename them.
#[allow(clippy::too_many_arguments)]
pub fn rho_heatmap(
    path: &Path,
    format: PlotFormat,
    title: &str,
    x_label: &str,
    y_label: &str,
    xs: &[f64],
    ys: &[f64],
    rho: &[Vec<f64>],
) -> Result<()> {
    if xs.is_empty() || ys.is_empty() || rho.len() != ys.len() || rho.iter().any(|r| r.len() != xs.len()) {
        return Err(Error::file(
            path.display().to_string(),
            "cannot draw: the grid is empty or ragged",
        ));
    }
    render(path, format, (1000, 700), |s, target| {
        let scale = s(1.0);
        match target {
            RenderTarget::Bitmap(buf, size) => {
                let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
                draw_heatmap(&root, scale, title, x_label, y_label, xs, ys, rho)?;
                root.present().map_err(e)
            }
            RenderTarget::Svg(buf, size) => {
                let root = SVGBackend::with_string(buf, size).into_drawing_area();
                draw_heatmap(&root, scale, title, x_label, y_label, xs, ys, rho)?;
                root.present().map_err(e)
            }
        }
    })
    .map(|_| ())
}
