//! Drawing a figure's parts with plotters: line charts with their axes and legend, the
//! three orthographic views with a colour bar, and point clouds.

#[allow(unused_imports)]
use super::*;

pub(super) fn color(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

/// Axis labels: plain numbers near 1, `1e-5` style far from it.
pub(super) fn number(v: f64) -> String {
    let a = v.abs();
    // Tick positions are sums of steps: a zero can come out as 1e-17.
    if a < 1e-10 {
        "0".into()
    } else if !(1e-3..1e6).contains(&a) {
        let e = a.log10().floor();
        let m = v / 10f64.powf(e);
        if (m.abs() - 1.0).abs() < 1e-9 {
            format!("{}e{}", if v < 0.0 { "-1" } else { "1" }, e as i64)
        } else {
            format!("{m:.1}e{}", e as i64)
        }
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The range of `values` padded by 5 % (on a log axis: in log space, positive values only).
pub(super) fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return if log { (0.1, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        let (a, b) = (lo.log10(), hi.log10());
        let pad = 0.05 * (b - a).max(0.2);
        (10f64.powf(a - pad), 10f64.powf(b + pad))
    } else {
        let pad = 0.05 * (hi - lo).max(1e-9 * hi.abs().max(1.0));
        (lo - pad, hi + pad)
    }
}

pub(super) fn draw_lines<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x_label: &str,
    y_label: &str,
    series: &[Curve],
    log_x: bool,
    log_y: bool,
) -> DrawResult<DB> {
    let xs = range(series.iter().flat_map(|s| s.2.iter().map(|p| p.0)), log_x);
    let ys = range(series.iter().flat_map(|s| s.2.iter().map(|p| p.1)), log_y);
    // One body for the four axis combinations: the coordinate types differ.
    macro_rules! chart {
        ($x:expr, $y:expr) => {{
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(48)
                .y_label_area_size(72)
                .build_cartesian_2d($x, $y)?;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style((FONT, 14))
                .axis_desc_style((FONT, 16))
                .x_label_formatter(&|v| number(*v))
                .y_label_formatter(&|v| number(*v))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()?;
            for (name, rgb, points) in series {
                let c = color(*rgb);
                let ok = |p: &&(f64, f64)| {
                    p.0.is_finite()
                        && p.1.is_finite()
                        && (!log_x || p.0 > 0.0)
                        && (!log_y || p.1 > 0.0)
                };
                chart
                    .draw_series(LineSeries::new(
                        points.iter().filter(ok).copied(),
                        c.stroke_width(2),
                    ))?
                    .label(name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                    });
                if points.iter().filter(ok).count() < 40 {
                    chart.draw_series(
                        points
                            .iter()
                            .filter(ok)
                            .map(|&p| Circle::new(p, 3, c.filled())),
                    )?;
                }
            }
            chart
                .configure_series_labels()
                .label_font((FONT, 14))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .position(SeriesLabelPosition::UpperRight)
                .draw()?;
        }};
    }
    match (log_x, log_y) {
        (false, false) => chart!(xs.0..xs.1, ys.0..ys.1),
        (true, false) => chart!((xs.0..xs.1).log_scale(), ys.0..ys.1),
        (false, true) => chart!(xs.0..xs.1, (ys.0..ys.1).log_scale()),
        (true, true) => chart!((xs.0..xs.1).log_scale(), (ys.0..ys.1).log_scale()),
    }
    Ok(())
}

pub(super) fn draw_views<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    canonical: &[[f32; 3]],
    truth: &[[f32; 3]],
    predicted: &[[f32; 3]],
    max_error: f64,
) -> DrawResult<DB> {
    let (panels, bar) = area.split_vertically(area.dim_in_pixel().1 - 70);
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in canonical.iter().chain(truth).chain(predicted) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    // One scale for all three views, so that lengths compare across panels.
    let span = (0..3).map(|k| hi[k] - lo[k]).fold(1e-9, f64::max) * 1.05;
    let mid: Vec<f64> = (0..3).map(|k| 0.5 * (lo[k] + hi[k])).collect();
    let views = [
        (0usize, 1usize, "x", "y"),
        (0, 2, "x", "z"),
        (2, 1, "z", "y"),
    ];
    for (panel, &(a, b, la, lb)) in panels.split_evenly((1, 3)).iter().zip(&views) {
        let mut chart = ChartBuilder::on(panel)
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .caption(format!("{la}–{lb}"), (FONT, 16))
            .build_cartesian_2d(
                mid[a] - span / 2.0..mid[a] + span / 2.0,
                mid[b] - span / 2.0..mid[b] + span / 2.0,
            )?;
        chart
            .configure_mesh()
            .x_desc(la)
            .y_desc(lb)
            .label_style((FONT, 12))
            .x_label_formatter(&|v| number(*v))
            .y_label_formatter(&|v| number(*v))
            .light_line_style(RGBColor(240, 240, 240))
            .draw()?;
        let at = |p: &[f32; 3]| (p[a] as f64, p[b] as f64);
        chart.draw_series(
            canonical
                .iter()
                .map(|p| Circle::new(at(p), 1, RGBColor(190, 190, 190).filled())),
        )?;
        chart.draw_series(truth.iter().map(|p| Circle::new(at(p), 1, BLACK.filled())))?;
        chart.draw_series(predicted.iter().zip(truth).map(|(p, t)| {
            let e: f64 = (0..3).map(|k| (p[k] - t[k]).abs() as f64).sum();
            Circle::new(at(p), 2, color(ramp(e / max_error.max(1e-12))).filled())
        }))?;
    }
    colour_bar(
        &bar,
        max_error,
        "L1 error",
        "grey: canonical   black: true   coloured: predicted",
    )
}

/// A horizontal colour bar of [`ramp`] from 0 to `max`, with its label and a note.
pub(super) fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    max: f64,
    label: &str,
    note: &str,
) -> DrawResult<DB> {
    let (x0, y0, w, h) = (24i32, 14i32, 300i32, 14i32);
    for i in 0..w {
        let c = color(ramp(i as f64 / (w - 1) as f64));
        area.draw(&Rectangle::new(
            [(x0 + i, y0), (x0 + i + 1, y0 + h)],
            c.filled(),
        ))?;
    }
    let style = TextStyle::from((FONT, 14).into_font()).color(&BLACK);
    area.draw(&Text::new("0".to_string(), (x0, y0 + h + 4), style.clone()))?;
    area.draw(&Text::new(
        format!("{label} {}", number(max)),
        (x0 + w - 110, y0 + h + 4),
        style.clone(),
    ))?;
    area.draw(&Text::new(note.to_string(), (x0 + w + 30, y0), style))?;
    Ok(())
}

pub(super) fn draw_points<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: &[[f32; 3]],
    colours: &[Rgb],
) -> DrawResult<DB> {
    let mut chart = ChartBuilder::on(area)
        .margin(4)
        .build_cartesian_2d(-2.5f64..2.5, -2.5f64..2.5)?;
    chart.draw_series(
        points
            .iter()
            .zip(colours)
            .map(|(p, &c)| Pixel::new((p[0] as f64, p[1] as f64), color(c))),
    )?;
    Ok(())
}
