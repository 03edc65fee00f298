//! The gap-filling report of a fit (`--holdout-observations`): doma's fill, the field
//! alone and every filler, measured on the same held-out observations.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::{RunConfig, field_everywhere};
use crate::Result;
use crate::data::sequence::Sequence;
use crate::field::MotionField;
use crate::gaps::blend::{Blend, fills_at};
use crate::gaps::{FieldPrediction, Filler, Marked, PerFiller};
use crate::metrics::EPE_SCALE;

/// Gap filling (`--holdout-observations`): on the observations of the fitted tracks that
/// the fit did not see, the error of doma's fill ([`crate::gaps::blend`]: the field's fill
/// blended with the classic fillers by validated weights), of the field alone, and of every
/// filler ([`Filler`]) on the same entries from the same observations.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GapReport {
    /// The hidden observations of the fitted tracks.
    pub entries: usize,
    /// The weights of doma's fill, learned on observations of the rest (absent in reports
    /// written before the blend).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blend: Option<Blend>,
    /// The EPE × 10⁴ (the L1 distance summed over x, y, z, averaged over the entries, in
    /// the normalised coordinates of the fit).
    pub epe_x1e4: GapErrors,
    /// The mean Euclidean distance to the truth, in the data's own units (mm for a C3D
    /// file's markers read in mm, metres for a `.npz` in metres).
    pub distance: GapErrors,
}

/// One error per way of filling, on the same entries; in JSON `doma`, `field` and one key
/// per filler ([`Filler::name`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct GapErrors {
    /// doma's fill (what `doma complete` writes, [`crate::gaps::blend`]).
    pub doma: f64,
    /// The fitted field alone, from each track's canonical position.
    pub field: f64,
    /// Each filler's (absent where a report was written before that filler existed).
    #[serde(flatten)]
    pub fillers: PerFiller<Option<f64>>,
}

/// The gap-filling report of `field` fitted under `config`: on the held-out observations
/// of the fitted tracks, doma's fill and the field alone beside every filler
/// ([`GapReport`]); `None` when nothing was held out. `placed` is the run's data as loaded
/// (the fillers use its observations, nothing the fit learned), `data` the same with the
/// canonical positions the fit learned ([`super::RunDir::load_data`]).
pub fn gap_report(
    field: &dyn MotionField,
    config: &RunConfig,
    placed: &Sequence,
    data: &Sequence,
    device: &Device,
) -> Result<Option<GapReport>> {
    let Some(held) = &data.held_out else {
        return Ok(None);
    };
    let (train_idx, _) = config.split_indices(data.trajectories.points())?;
    let train = data.trajectories.select_points(&train_idx)?;
    let given = placed.trajectories.select_points(&train_idx)?;
    let mut row = vec![usize::MAX; data.trajectories.points()];
    for (r, &i) in train_idx.iter().enumerate() {
        row[i] = r;
    }
    // The entries of fitted tracks, as (frame, fitted row), with their truth.
    let (entries, truth): (Vec<(usize, usize)>, Vec<[f32; 3]>) = held
        .entries
        .iter()
        .zip(&held.truth)
        .filter(|((_, i), _)| row[*i] != usize::MAX)
        .map(|(&(k, i), &p)| ((k, row[i]), p))
        .unzip();
    if entries.is_empty() {
        return Ok(None);
    }
    let (t, n) = (given.frames(), given.points());
    let mut seen = given.observed().map_or(vec![true; t * n], <[bool]>::to_vec);
    let mut positions = given.positions().to_vec();
    // The blind validation spans are observations the fill has, though the field does not.
    let mut blind = Vec::new();
    if let Some(b) = &placed.blind {
        for (&(k, i), p) in b.entries.iter().zip(&b.truth) {
            if row[i] != usize::MAX {
                let e = k * n + row[i];
                positions[3 * e..3 * e + 3].copy_from_slice(p);
                seen[e] = true;
                blind.push((k, row[i]));
            }
        }
    }
    let tracks = Marked::new(t, n, &positions, &seen);
    let predicted = field_everywhere(field, &train, device)?;
    // doma's fill and its fillers (the field's fills and the classic ones) at the entries.
    let prediction = FieldPrediction::new(n, &predicted, train.canonical(), tracks.observed);
    let fills = fills_at(
        &tracks,
        &prediction,
        config.fit.seed,
        &blind,
        &entries,
        &config.fit.validation(),
    );
    let field_alone: Vec<[f32; 3]> = entries
        .iter()
        .map(|&(k, r)| {
            let e = 3 * (k * n + r);
            [predicted[e], predicted[e + 1], predicted[e + 2]]
        })
        .collect();
    let fillers = Filler::ALL.map(|f| fills.filler(f));
    let scale = data.scale as f64;
    let errors = |metric: &dyn Fn(&[f32; 3], &[f32; 3]) -> f64| {
        let mean = |pred: &[[f32; 3]]| {
            pred.iter()
                .zip(&truth)
                .map(|(a, b)| metric(a, b))
                .sum::<f64>()
                / entries.len() as f64
        };
        GapErrors {
            doma: mean(&fills.doma),
            field: mean(&field_alone),
            fillers: PerFiller::from_fn(|f| Some(mean(&fillers[f.index()]))),
        }
    };
    let l1 = |a: &[f32; 3], b: &[f32; 3]| {
        EPE_SCALE * (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum::<f64>()
    };
    let euclid = |a: &[f32; 3], b: &[f32; 3]| {
        scale
            * (0..3)
                .map(|c| ((a[c] - b[c]) as f64).powi(2))
                .sum::<f64>()
                .sqrt()
    };
    Ok(Some(GapReport {
        entries: entries.len(),
        blend: Some(fills.blend.in_units(scale)),
        epe_x1e4: errors(&l1),
        distance: errors(&euclid),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_name_every_filler_and_earlier_reports_still_open() {
        // A report written before the fillers' names: `carried`, no `framewise`.
        let old = r#"{"doma": 1.0, "field": 2.0, "carried": 3.0, "linear": 4.0,
                      "spline": 5.0, "neighbours": 6.0, "low_rank": 7.0}"#;
        let e: GapErrors = serde_json::from_str(old).unwrap();
        assert_eq!((e.doma, e.field), (1.0, 2.0));
        assert_eq!(e.fillers[Filler::FieldFill], Some(3.0));
        assert_eq!(e.fillers[Filler::IterativePca], Some(7.0));
        assert_eq!(e.fillers[Filler::FieldFillFramewise], None);
        // Written back under today's names, the missing one left out.
        let text = serde_json::to_string(&e).unwrap();
        assert_eq!(
            text,
            r#"{"doma":1.0,"field":2.0,"field_fill":3.0,"spline":5.0,"neighbours":6.0,"iterative_pca":7.0,"linear":4.0}"#
        );
        assert_eq!(serde_json::from_str::<GapErrors>(&text).unwrap(), e);
        // A blend's weights of before `framewise` existed read it as 0.
        let w: crate::gaps::blend::Weights = serde_json::from_str(
            r#"{"carried": 0.5, "spline": 0.5, "neighbours": 0, "low_rank": 0, "linear": 0}"#,
        )
        .unwrap();
        assert_eq!(w[Filler::FieldFill], 0.5);
        assert_eq!(w[Filler::FieldFillFramewise], 0.0);
        let names: Vec<&str> = Filler::ALL.iter().map(|f| f.name()).collect();
        let json: serde_json::Value = serde_json::to_value(w).unwrap();
        let keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        assert_eq!(keys, sorted);
    }
}
