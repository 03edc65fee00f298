//! The flag groups that several subcommands share (device, experiment, regulariser
//! weights and their search, clips, sequences, alignment models) and the value parsers
//! behind them.

use std::path::{Path, PathBuf};

use clap::ValueEnum;

pub use crate::run::fraction;

use crate::backend::BackendKind;
use crate::{DomaError, Result};

/// The compute backend of a subcommand that runs on one device.
#[derive(clap::Args, Debug, Clone)]
pub struct DeviceArgs {
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub backend: BackendKind,
}

/// The flags every experiment shares: backend, seed, progress and the JSON records.
#[derive(clap::Args, Debug, Clone)]
pub struct ExperimentArgs {
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub backend: BackendKind,
    /// Seed of the split, the weights, the samples and the frame order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// Also write one JSON record per run to this file (atomically).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl ExperimentArgs {
    /// Fails before minutes of work when the JSON file's folder does not exist.
    pub fn check_json(&self) -> Result<()> {
        match &self.json {
            Some(path) => check_output_folder(path),
            None => Ok(()),
        }
    }

    /// Writes `records` to the JSON file, if one was asked for, and says so.
    pub fn write_json<T: serde::Serialize>(&self, records: &T) -> Result<()> {
        if let Some(path) = &self.json {
            crate::io::save_json(records, path)?;
            eprintln!("wrote {}", path.display());
        }
        Ok(())
    }
}

/// Fails early, before minutes of work, when `path` cannot be written (its folder is
/// missing or not writable).
pub fn check_output_folder(path: &Path) -> Result<()> {
    crate::io::check_writable(path)
}

/// A comma-separated list of a library enum's values, or `all` of them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Selection<T> {
    /// The values, in the order given (`all`: the enum's order).
    pub items: Vec<T>,
    /// Whether `all` was given.
    pub all: bool,
}

/// The clap value parser of a [`Selection`]: `a,b,c` or `all`.
pub fn selection<T: ValueEnum + Clone + Send + Sync + 'static>(
    s: &str,
) -> std::result::Result<Selection<T>, String> {
    if s.trim() == "all" {
        return Ok(Selection {
            items: T::value_variants().to_vec(),
            all: true,
        });
    }
    let items = s
        .split(',')
        .map(|part| T::from_str(part.trim(), true))
        .collect::<std::result::Result<Vec<T>, String>>()?;
    if items.is_empty() {
        return Err("an empty list".into());
    }
    Ok(Selection { items, all: false })
}

/// A finite, non-negative float.
pub fn non_negative(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("`{s}` must be finite and non-negative"))
    }
}

/// The weights of the smoothness ("-H") and elasticity ("-E") regularisers: a number, or
/// `auto` (chosen by validation on held-out training points).
#[derive(clap::Args, Debug, Clone)]
pub struct RegWeightArgs {
    /// The weight of the smoothness loss `L_H` (Eq. 13) with --reg h, or `auto`.
    #[arg(long, default_value = "0.1", allow_negative_numbers = true)]
    pub h_weight: crate::train::select::Weight,
    /// The weight of the elasticity loss with --reg e, or `auto`.
    #[arg(long, default_value = "0.01", allow_negative_numbers = true)]
    pub e_weight: crate::train::select::Weight,
    /// How an `auto` weight is searched.
    #[command(flatten)]
    pub search: WeightSearchArgs,
}

/// How an `auto` weight is searched: the grid, the validation fraction of the training
/// points and the short budget (cost: grid × budget iterations per model before its fit).
#[derive(clap::Args, Debug, Clone)]
pub struct WeightSearchArgs {
    /// With a weight of `auto`: the weights tried (comma-separated; include 0, no
    /// regulariser).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,1e-4,1e-3,1e-2,1e-1,1",
        allow_negative_numbers = true
    )]
    pub weight_grid: Vec<f64>,
    /// With `auto`: the fraction of the training points held out to score each weight.
    #[arg(long, default_value_t = 0.2, allow_negative_numbers = true)]
    pub validation_fraction: f64,
    /// With `auto`: iterations of each short fit of the search.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    pub search_iters: u64,
}

impl WeightSearchArgs {
    /// The search these flags describe, checked.
    pub fn search(&self) -> Result<crate::train::select::WeightSearch> {
        let search = crate::train::select::WeightSearch {
            grid: self.weight_grid.clone(),
            validation_fraction: self.validation_fraction,
            iterations: self.search_iters as usize,
        };
        search.validate()?;
        Ok(search)
    }
}

/// Refuses a list of hidden widths that holds 0, naming the flag.
pub fn check_widths(widths: &[usize]) -> Result<()> {
    if widths.contains(&0) {
        return Err(DomaError::Usage(
            "--widths: a hidden width must be at least 1".into(),
        ));
    }
    Ok(())
}

/// Which part of a sequence to use, and its faces (`fit`, `novel-points`, `mesh-alignment`).
#[derive(clap::Args, Debug, Clone)]
pub struct ClipArgs {
    /// An OBJ whose vertices are the points in order, for the faces (default: NAME.obj next
    /// to a .traj, or the .anime's own faces).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// A clip of the frames, `A..B` (B excluded) or `A..=B`.
    #[arg(long, value_parser = crate::data::parse_frame_range)]
    pub frames: Option<std::ops::Range<usize>>,
    /// Keep every N-th frame of the clip.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub stride: Option<u64>,
}

/// Where a mesh experiment's sequence comes from (`novel-points`, `mesh-alignment`).
#[derive(clap::Args, Debug, Clone)]
pub struct SequenceArgs {
    /// The sequence: .traj, .anime, .npy, .npz, .c3d or a folder of OBJ frames (default: the
    /// crate's data/cdp_male_wave.traj).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The clip and the faces.
    #[command(flatten)]
    pub clip: ClipArgs,
}

impl SequenceArgs {
    /// Loads the sequence (every `default_stride`-th frame unless `--stride` says
    /// otherwise), named after the file, the clip and the stride.
    pub fn load(&self, default_stride: usize) -> Result<crate::data::sequence::Sequence> {
        let data = self
            .data
            .clone()
            .unwrap_or_else(crate::experiments::meshes::default_data);
        let clip = &self.clip;
        let stride = clip.stride.map_or(default_stride, |s| s as usize);
        let mut seq = crate::data::sequence::load_sequence(
            &data,
            clip.mesh.as_deref(),
            clip.frames.clone(),
            stride,
        )?;
        if let Some(r) = &clip.frames {
            seq.name = format!("{}[{}..{}]", seq.name, r.start, r.end);
        }
        if stride > 1 {
            seq.name = format!("{}/{stride}", seq.name);
        }
        Ok(seq)
    }

    /// Says what a mesh experiment is about to fit.
    pub fn announce(
        experiment: &str,
        seq: &crate::data::sequence::Sequence,
        iterations: u64,
        backend: BackendKind,
    ) {
        eprintln!(
            "{experiment} on {}: {} frames, {} vertices, {iterations} iterations, backend {backend}",
            seq.name,
            seq.trajectories.frames(),
            seq.trajectories.points(),
        );
    }
}

/// The models of the Tab. 3 and Tab. A8 comparisons (`mesh-alignment`, `fluid`).
#[derive(clap::Args, Debug, Clone)]
pub struct AlignModelArgs {
    /// The models (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "dpf,trans,affinity"
    )]
    pub model: Vec<crate::experiments::meshes::AlignModel>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::Variant;

    #[test]
    fn a_selection_is_a_list_or_all() {
        let all = selection::<Variant>("all").unwrap();
        assert_eq!((all.items, all.all), (Variant::ALL.to_vec(), true));
        let two = selection::<Variant>("affinity,trans").unwrap();
        assert_eq!(two.items, vec![Variant::Affinity, Variant::Trans]);
        assert!(!two.all);
        let err = selection::<Variant>("trans,bones").unwrap_err();
        assert!(err.contains("bones"), "{err}");
    }

    #[test]
    fn number_flags_are_checked() {
        assert_eq!(non_negative("0.5"), Ok(0.5));
        assert!(non_negative("-1").is_err() && non_negative("inf").is_err());
        assert!(fraction("0").is_err() && fraction("1").is_err() && fraction("0.75").is_ok());
        assert!(
            check_widths(&[32, 0])
                .unwrap_err()
                .to_string()
                .contains("--widths")
        );
    }
}

/// A named recipe and a stop on convergence, for every subcommand that starts fits.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct RecipeArgs {
    /// A named recipe: `paper` (the paper's protocol, the default), `fast` (1.5 times the
    /// learning rate, warm-up and cosine decay, 256 training points and 64 `L_H` samples
    /// per step) or `soap` (`fast` over 400 iterations at 3 times the rate, stepped by SOAP; the fused step
    /// only); docs/speed.md. Other flags override its settings; they all go into the
    /// run's config.
    #[arg(long, value_enum)]
    pub recipe: Option<crate::train::Recipe>,
    /// Stop once the EPE on a held-back tenth of the training tracks (checked every 10
    /// iterations) has not improved by 1 % for PATIENCE iterations, after a cool-down of
    /// PATIENCE more iterations whose learning rate falls linearly to 0; the held-back
    /// tracks are not fitted.
    #[arg(long, value_name = "PATIENCE", value_parser = clap::value_parser!(u64).range(1..))]
    pub until_converged: Option<u64>,
}

impl RecipeArgs {
    /// The library's form of these flags.
    pub fn choice(&self) -> crate::train::RecipeChoice {
        crate::train::RecipeChoice {
            recipe: self.recipe,
            until_converged: self.until_converged.map(|p| p as usize),
        }
    }
}

/// Which gaps a completion fills and by what: `doma complete`'s and `doma fill`'s flags
/// ([`crate::run::FillPolicy`]).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct FillPolicyArgs {
    /// Fill gaps of at most this length only: N frames of the input, or Xs seconds (a
    /// .c3d or .trc input's rate); longer gaps are left as the input holds them (NaN in a
    /// .npz), and counted.
    #[arg(long, value_name = "N|Xs")]
    pub max_gap: Option<crate::run::MaxGap>,
    /// Fill before a track's first observation and after its last too (`=false`: not); the
    /// count is printed. By default a tracker's output (a PointOdyssey or TAPVid-3D .npz)
    /// is filled at every point of every frame, and a motion-capture recording (.c3d,
    /// .trc) or other tracks only in gaps with observations on both sides.
    #[arg(long, num_args = 0..=1, default_missing_value = "true", require_equals = true, value_name = "BOOL")]
    pub extrapolate: Option<bool>,
    /// Fill with one filler alone instead of doma's fill (the blend); `chain` is the
    /// default of `doma fill`, and the field's fills need a fit. The
    /// snake_case names of reports and Python are accepted too.
    #[arg(long, value_name = "FILLER")]
    pub method: Option<crate::gaps::Filler>,
}

/// The fillers as the command line lists and reads them: every one of
/// [`crate::gaps::Filler::ALL`] by its kebab-case [`crate::gaps::Filler::flag`], its report
/// name and former names as aliases.
impl ValueEnum for crate::gaps::Filler {
    fn value_variants<'a>() -> &'a [Self] {
        &crate::gaps::Filler::ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        let value = clap::builder::PossibleValue::new(self.flag()).help(self.label());
        let aliases = std::iter::once(self.name())
            .filter(|name| *name != self.flag())
            .chain(self.former_names().iter().copied());
        Some(aliases.fold(value, |v, alias| v.alias(alias)))
    }
}

impl FillPolicyArgs {
    /// The policy these flags ask for.
    pub fn policy(&self) -> crate::run::FillPolicy {
        crate::run::FillPolicy {
            max_gap: self.max_gap,
            extrapolate: self.extrapolate,
            method: self.method,
        }
    }
}
