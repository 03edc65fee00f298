//! A filled recording's report as one self-contained HTML page (`NAME.gaps.html` beside the
//! output): the table of filled gaps, the flagged first, and for each of the gaps to check a
//! small plot of x, y and z against time: the marker's observations around the gap, the
//! fill, and the band of its expected error. Every name from a file is escaped.

use std::fmt::Write as _;
use std::path::Path;

use super::Completion;
use super::gap_table::{
    GapTable, gap_rows, gaps_csv, gaps_csv_path, gaps_html_path, names_and_rate,
};
use crate::Result;
use crate::data::layout::TrackFile;
use crate::data::sequence::read_points;

/// The gaps plotted, the flagged first: past this many, the table alone lists them.
pub const PLOTTED_GAPS: usize = 60;

/// `text` with `&`, `<`, `>`, `"` and `'` escaped for HTML.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Writes the table ([`gaps_csv`]) and the page ([`gaps_html`]) of the
/// gaps of `input` filled into `output`, beside it; returns the table.
pub fn write_gap_report(
    input: &Path,
    output: &Path,
    c: &Completion,
    flag_above_mm: f64,
) -> Result<GapTable> {
    let table = gap_rows(input, c, flag_above_mm)?;
    let (_, rate) = names_and_rate(input)?;
    let html = gaps_html(input, output, &table, rate)?;
    crate::io::write_atomic(&gaps_csv_path(output), gaps_csv(&table).as_bytes())?;
    crate::io::write_atomic(&gaps_html_path(output), html.as_bytes())?;
    Ok(table)
}

/// The page for the recording `input` filled into `output`, whose gaps are `table`.
pub fn gaps_html(
    input: &Path,
    output: &Path,
    table: &GapTable,
    rate: Option<f64>,
) -> Result<String> {
    let before = read_points(input, &TrackFile::default())?;
    let after = read_points(output, &TrackFile::default())?;
    let n = before.tracks.points();
    let units = table.units.as_deref().unwrap_or("");
    let name = input
        .file_name()
        .map_or(String::new(), |f| f.to_string_lossy().into_owned());
    let mut page = String::new();
    let flagged = table.rows.iter().filter(|r| r.flagged).count();
    let _ = write!(
        page,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>{} — filled gaps</title>\
         <style>body{{font:14px sans-serif;margin:2em}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}\
         td:first-child{{text-align:left}}tr.flag{{background:#fee}}\
         .gap{{display:inline-block;margin:6px;vertical-align:top}}</style></head><body>\
         <h1>{}</h1><p>{} gaps filled, {flagged} flagged (expected error above the threshold), \
         written to {}.</p>",
        escape(&name),
        escape(&name),
        table.rows.len(),
        escape(&output.display().to_string()),
    );
    match table.calibration {
        Some(c) => {
            let _ = write!(
                page,
                "<p>Expected error: the donor fillers' spread over the gap times {:.2}, the \
                 median ratio of the chain fill's error to the spread on {} spans of this \
                 recording hidden on purpose.</p>",
                c.factor, c.spans
            );
        }
        None => page.push_str("<p>Too few observations to calibrate an expected error.</p>"),
    }
    gap_rows_html(&mut page, table, units);
    page.push_str("</table><h2>The gaps to check</h2>");
    let (t, positions_before, seen) = (
        before.tracks.frames(),
        before.tracks.positions().to_vec(),
        before.tracks.observed().to_vec(),
    );
    let positions_after = after.tracks.positions();
    for r in table.rows.iter().take(PLOTTED_GAPS) {
        let i = r.track;
        if i >= n || positions_after.len() != positions_before.len() {
            continue;
        }
        let pad = (r.last_frame - r.first_frame + 1).max(10);
        let from = r.first_frame.saturating_sub(pad);
        let to = (r.last_frame + pad + 1).min(t);
        let _ = write!(
            page,
            "<div class=\"gap\"><b>{}</b> frames {}–{}{}<br>",
            escape(&r.marker),
            r.first_frame,
            r.last_frame,
            r.expected_error.map_or(String::new(), |e| format!(
                ", expected error {e:.2} {}",
                escape(units)
            ))
        );
        for d in 0..3 {
            let at = |p: &[f32], k: usize| p[3 * (k * n + i) + d] as f64;
            let observed: Vec<(usize, f64)> = (from..to)
                .filter(|&k| seen[k * n + i])
                .map(|k| (k, at(&positions_before, k)))
                .collect();
            let fill: Vec<(usize, f64)> = (r.first_frame..=r.last_frame)
                .map(|k| (k, at(positions_after, k)))
                .filter(|(_, v)| v.is_finite())
                .collect();
            page.push_str(&panel(
                ["x", "y", "z"][d],
                from,
                to,
                &observed,
                &fill,
                r.expected_error,
                rate,
            ));
        }
        page.push_str("</div>");
    }
    page.push_str("</body></html>\n");
    Ok(page)
}

/// The table of `table`'s gaps, one row each, the flagged ones marked.
fn gap_rows_html(page: &mut String, table: &GapTable, units: &str) {
    page.push_str(
        "<table><tr><th>marker</th><th>first frame</th><th>last frame</th><th>start (s)</th>\
         <th>length (s)</th><th>past ends</th><th>filled by</th><th>expected error</th></tr>",
    );
    for r in &table.rows {
        let time = |t: Option<f64>| t.map_or(String::new(), |t| format!("{t:.3}"));
        let expected = r
            .expected_error
            .map_or(String::new(), |e| format!("{e:.2} {}", escape(units)));
        let _ = write!(
            page,
            "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{expected}</td></tr>",
            if r.flagged { " class=\"flag\"" } else { "" },
            escape(&r.marker),
            r.first_frame,
            r.last_frame,
            time(r.start_s),
            time(r.length_s),
            r.past_ends,
            r.filled_by,
        );
    }
}

/// One coordinate against time, as an inline SVG: the observations as dots, the fill as a
/// line, its expected error as a band around it.
fn panel(
    axis: &str,
    from: usize,
    to: usize,
    observed: &[(usize, f64)],
    fill: &[(usize, f64)],
    band: Option<f64>,
    rate: Option<f64>,
) -> String {
    let (w, h) = (220.0, 70.0);
    let b = band.unwrap_or(0.0);
    let values = observed.iter().chain(fill).map(|(_, v)| *v);
    let lo = values.clone().fold(f64::INFINITY, f64::min) - b;
    let hi = values.fold(f64::NEG_INFINITY, f64::max) + b;
    if !(lo.is_finite() && hi.is_finite()) {
        return String::new();
    }
    let span = (hi - lo).max(1e-9);
    let x = |k: usize| 4.0 + (w - 8.0) * (k - from) as f64 / ((to - from).max(2) - 1) as f64;
    let y = |v: f64| 4.0 + (h - 8.0) * (hi - v) / span;
    let mut svg = format!(
        "<svg width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" role=\"img\"><title>{axis} \
         against {}</title><rect width=\"{w}\" height=\"{h}\" fill=\"#fafafa\" stroke=\"#ddd\"/>",
        if rate.is_some() { "time" } else { "frame" }
    );
    if b > 0.0 && !fill.is_empty() {
        let upper: Vec<String> = fill
            .iter()
            .map(|&(k, v)| format!("{:.1},{:.1}", x(k), y(v + b)))
            .collect();
        let lower: Vec<String> = fill
            .iter()
            .rev()
            .map(|&(k, v)| format!("{:.1},{:.1}", x(k), y(v - b)))
            .collect();
        let _ = write!(
            svg,
            "<polygon points=\"{} {}\" fill=\"#f4a58a\" fill-opacity=\"0.4\"/>",
            upper.join(" "),
            lower.join(" ")
        );
    }
    for &(k, v) in observed {
        let _ = write!(
            svg,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"1.2\" fill=\"#333\"/>",
            x(k),
            y(v)
        );
    }
    if !fill.is_empty() {
        let line: Vec<String> = fill
            .iter()
            .map(|&(k, v)| format!("{:.1},{:.1}", x(k), y(v)))
            .collect();
        let _ = write!(
            svg,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"#c0392b\" stroke-width=\"1.5\"/>",
            line.join(" ")
        );
    }
    let _ = write!(
        svg,
        "<text x=\"6\" y=\"14\" font-size=\"11\">{axis}</text></svg>"
    );
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_escaped() {
        assert_eq!(
            escape("<b a=\"x\">&'"),
            "&lt;b a=&quot;x&quot;&gt;&amp;&#39;"
        );
    }

    #[test]
    fn a_panel_draws_the_band_the_fill_and_the_observations() {
        let observed = [(0, 1.0), (1, 2.0), (6, 3.0)];
        let fill = [(2, 2.2), (3, 2.4), (4, 2.6), (5, 2.8)];
        let svg = panel("x", 0, 7, &observed, &fill, Some(0.5), Some(100.0));
        assert_eq!(svg.matches("<circle").count(), 3);
        assert_eq!(svg.matches("<polyline").count(), 1);
        assert_eq!(svg.matches("<polygon").count(), 1);
        assert!(panel("x", 0, 7, &[], &[], None, None).is_empty());
    }
}
