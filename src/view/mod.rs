//! `doma view`: one self-contained HTML file with a WebGL viewer of a fitted run: play and
//! pause, a frame slider, an orbit camera (drag to turn, wheel to zoom), the predicted and
//! the true points (or the warped mesh) coloured by each point's end-point error, with a
//! legend. The page loads nothing from the network: the frames are embedded in it as
//! base64 arrays, and the viewer is plain WebGL (`viewer.html`, no library).

use std::path::Path;

use base64::Engine;
use burn::tensor::Device;
use serde::Serialize;

use crate::data::mesh::as_points;
use crate::data::sequence::Sequence;
use crate::data::textured::TexturedMesh;
use crate::metrics::EPE_SCALE;
use crate::run::{OpenRun, RunDir};
use crate::{DomaError, Result};

const TEMPLATE: &str = include_str!("viewer.html");
const SLOT: &str = "/*DOMA_DATA*/null";

/// What the page embeds (`DATA` in `viewer.html`).
#[derive(Serialize)]
struct ViewData {
    name: String,
    frames: usize,
    vertices: usize,
    first_frame: usize,
    fps: f32,
    /// `[T, V, 3]` float32, the data's units.
    pred: String,
    /// `[T, V, 3]` float32, or null with a user's mesh.
    truth: Option<String>,
    /// `[F, 3]` uint32, or null for a point cloud.
    triangles: Option<String>,
    /// `[T, V]` float32: each point's EPE in the legend's units, or null.
    error: Option<String>,
    /// The ramp's top: the 95th percentile of the errors (larger ones saturate).
    error_max: f64,
    error_units: String,
    /// The vertical axis, 0..3: the user's, else the longest side of the box when it is
    /// clearly the longest (Z-up characters), else y.
    up: usize,
    /// `[T, V]` uint8: 1 where the run's data observed the point, 0 where the field fills
    /// it; null for complete data or a user's mesh.
    observed: Option<String>,
}

/// A coordinate axis, for `--up`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Axis {
    /// x.
    X,
    /// y.
    Y,
    /// z.
    Z,
}

impl Axis {
    /// The axis' index, 0..3.
    pub fn index(self) -> usize {
        self as usize
    }
}

fn b64<T: bytemuck::Pod>(values: &[T]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytemuck::cast_slice(values))
}

/// The normalised vertices shown, their triangles, and whether they are the run's points.
type ViewShape = (Vec<[f32; 3]>, Option<Vec<[u32; 3]>>, bool);

/// The 95th percentile of `errors` (0 for none).
fn percentile_95(mut errors: Vec<f32>) -> f32 {
    errors.sort_by(f32::total_cmp);
    errors.get(errors.len() * 95 / 100).copied().unwrap_or(0.0)
}

/// The axis to show upwards: the longest extent of `pred` (`[.., 3]` flat) when it is
/// clearly the longest (1.3 times the others), else y.
fn up_axis(pred: &[f32]) -> usize {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in pred.chunks_exact(3) {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let ext: Vec<f32> = (0..3).map(|c| hi[c] - lo[c]).collect();
    let longest = (0..3)
        .max_by(|&a, &b| ext[a].total_cmp(&ext[b]))
        .unwrap_or(1);
    let clearly = (0..3)
        .filter(|&c| c != longest)
        .all(|c| ext[longest] > 1.3 * ext[c]);
    if clearly { longest } else { 1 }
}

/// The shape to show, normalised as the run's data: `mesh`'s vertices and triangles, or
/// the run's own points and faces; and whether its vertices are the run's points (with a
/// truth to compare to).
fn view_shape(mesh: Option<&Path>, own: &Sequence) -> Result<ViewShape> {
    Ok(match mesh {
        Some(path) => {
            let textured = TexturedMesh::read(path)?;
            let mut tris = Vec::new();
            let mut offset = 0u32;
            for part in &textured.parts {
                tris.extend(part.triangles.iter().map(|t| t.map(|i| i + offset)));
                offset += part.positions.len() as u32;
            }
            let norm: Vec<[f32; 3]> = textured
                .positions()
                .iter()
                .map(|v| std::array::from_fn(|c| (v[c] - own.center[c]) / own.scale))
                .collect();
            (norm, Some(tris).filter(|t| !t.is_empty()), false)
        }
        None => (
            as_points(own.trajectories.canonical()),
            own.faces.clone(),
            true,
        ),
    })
}

/// The viewer page of the run in `run`: its own points (with its faces, if any) against
/// the truth, or the user's `mesh` (any OBJ in the data's units) warped; `frames` (default
/// all of the run's); `up` the vertical axis (default: guessed from the box). Where the
/// run's data did not observe a point, it is drawn in the "filled" colour, its error is not
/// counted, and the true layer shows it where the field put it.
pub fn view_html(
    run: &RunDir,
    mesh: Option<&Path>,
    frames: Option<std::ops::Range<usize>>,
    up: Option<Axis>,
    device: &Device,
) -> Result<String> {
    let OpenRun {
        config,
        field,
        data: own,
        frames: range,
    } = run.open(frames, device)?;
    let total = own.trajectories.frames();
    let to_data =
        |p: &[f32; 3]| -> [f32; 3] { std::array::from_fn(|c| p[c] * own.scale + own.center[c]) };
    let (canonical, triangles, with_truth) = view_shape(mesh, &own)?;
    let v = canonical.len();
    let mut pred = Vec::with_capacity(range.len() * v * 3);
    let mut truth = Vec::new();
    let mut error = Vec::new();
    let masked = with_truth && own.trajectories.observed().is_some();
    let mut observed: Vec<u8> = Vec::new();
    let mut seen_errors = Vec::new();
    crate::warp::warp_frames(&field, &canonical, range.clone(), total, device, |k, y| {
        if with_truth {
            let t = own.trajectories.frame(k);
            for (i, p) in y.iter().enumerate() {
                let seen = own.trajectories.is_observed(k, i);
                let e: f64 = (0..3)
                    .map(|c| (p[c] as f64 - t[3 * i + c] as f64).abs())
                    .sum();
                let e = if seen { (e * EPE_SCALE) as f32 } else { 0.0 };
                error.push(e);
                if seen {
                    seen_errors.push(e);
                }
                if masked {
                    observed.push(u8::from(seen));
                }
                // An unobserved point has no truth: the true layer shows the field's.
                let q = if seen {
                    [t[3 * i], t[3 * i + 1], t[3 * i + 2]]
                } else {
                    *p
                };
                truth.extend(to_data(&q));
            }
        }
        pred.extend(y.iter().flat_map(to_data));
        Ok(())
    })?;
    if let Some(i) = pred.iter().position(|c| !c.is_finite()) {
        return Err(DomaError::InvalidData(format!(
            "frame {}: vertex {} warps to a non-finite position",
            range.start + i / (3 * v),
            (i / 3) % v
        )));
    }
    let error_max = percentile_95(seen_errors).max(1e-6) as f64;
    let up = up.map(Axis::index).unwrap_or_else(|| up_axis(&pred));
    let name = format!(
        "{} — {}",
        run.dir
            .file_name()
            .map_or("run".into(), |n| n.to_string_lossy().into_owned()),
        config.fit.model.paper_name()
    );
    let data = ViewData {
        name,
        frames: range.len(),
        vertices: v,
        first_frame: range.start,
        fps: 12.0,
        pred: b64(&pred),
        truth: with_truth.then(|| b64(&truth)),
        triangles: triangles.map(|t| b64(t.as_flattened())),
        error: with_truth.then(|| b64(&error)),
        error_max,
        error_units: "×1e-4, normalised units".into(),
        up,
        observed: masked.then(|| b64(&observed)),
    };
    let json = serde_json::to_string(&data)
        .map_err(|e| DomaError::InvalidData(format!("cannot serialise the view: {e}")))?;
    Ok(TEMPLATE.replacen(SLOT, &script_json(&json), 1))
}

/// JSON made safe to embed in an HTML `<script>` element: `<`, `>` and `&` as `\u003c`,
/// `\u003e` and `\u0026` (so that no `</script>`, `<!--` or `<script` in a name can close
/// the element or switch the parser into its escaped states), and U+2028/U+2029 escaped for
/// older JavaScript parsers. The escapes stay valid JSON and denote the same strings;
/// serde writes these characters only inside strings.
pub fn script_json(json: &str) -> String {
    let mut out = String::with_capacity(json.len());
    for c in json.chars() {
        match c {
            '<' => out.push_str("\\u003c"),
            '>' => out.push_str("\\u003e"),
            '&' => out.push_str("\\u0026"),
            '\u{2028}' => out.push_str("\\u2028"),
            '\u{2029}' => out.push_str("\\u2029"),
            c => out.push(c),
        }
    }
    out
}

/// Writes [`view_html`] to `out`, atomically.
pub fn write_view(
    run: &RunDir,
    mesh: Option<&Path>,
    frames: Option<std::ops::Range<usize>>,
    up: Option<Axis>,
    out: &Path,
    device: &Device,
) -> Result<usize> {
    crate::io::check_writable(out)?;
    let data = run.load_config()?.data;
    let inputs: Vec<&Path> = std::iter::once(data.as_path()).chain(mesh).collect();
    crate::io::check_output(out, Some(&run.dir), &inputs)?;
    let html = view_html(run, mesh, frames, up, device)?;
    crate::io::write_atomic(out, html.as_bytes())?;
    Ok(html.len())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_template_has_one_data_slot() {
        assert_eq!(super::TEMPLATE.matches(super::SLOT).count(), 1);
    }

    #[test]
    fn embedded_json_cannot_close_the_script_and_keeps_its_strings() {
        let hostile = "<!--<script>x</script>&amp;\u{2028}\u{2029}\"'";
        let json = serde_json::to_string(&serde_json::json!({ "name": hostile })).unwrap();
        let safe = super::script_json(&json);
        for bad in ['<', '>', '&', '\u{2028}', '\u{2029}'] {
            assert!(!safe.contains(bad), "{bad:?} left in {safe}");
        }
        let back: serde_json::Value = serde_json::from_str(&safe).unwrap();
        assert_eq!(back["name"], hostile);
    }
}
