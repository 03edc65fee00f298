//! `doma complete`: a fitted run's tracks at every frame, gaps filled.

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::data::layout::Layout;
use crate::gaps::Filler;
use crate::run::{RunDir, complete_run_with};

/// The flags of `doma complete`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Write every track of a fitted run at every frame (.npz, or .c3d from a C3D input), gaps filled by the field"
)]
pub struct CompleteArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The file to write: a .npz (`tracks` f32 [T, N, 3] and `observed` bool [T, N]), or,
    /// when the run fitted a .c3d, that file with only its filled markers written (residual
    /// 0: computed, not measured), everything else kept.
    #[arg(long)]
    pub out: PathBuf,
    /// Write a tracker's keys instead (pointodyssey: trajs_3d, visibs, valids; tapvid3d:
    /// tracks_XYZ, visibility).
    #[arg(long, value_enum)]
    pub layout: Option<Layout>,
    /// Which gaps are filled, and by what.
    #[command(flatten)]
    pub fill: crate::cli::FillPolicyArgs,
    /// Also write the weights the fill used, per class of gap, with what each class's
    /// weights gave on its held-out validation spans beside the best filler alone there
    /// (JSON, in the data's units): what the printout says, for a script.
    #[arg(long, value_name = "FILE.json")]
    pub blend: Option<PathBuf>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the completed tracks.
pub fn run(args: &CompleteArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let policy = args.fill.policy();
    let c = complete_run_with(
        &RunDir::new(&args.run),
        &args.out,
        args.layout,
        policy,
        &device,
    )?;
    eprintln!(
        "wrote {}: {} tracks × {} frames, {} observed entries kept, {} filled",
        args.out.display(),
        c.tracks,
        c.frames,
        c.observed,
        c.filled
    );
    if c.extrapolated > 0 {
        eprintln!(
            "  {} entries extrapolated, before a track's first observation or after its last",
            c.extrapolated
        );
    }
    if c.unfilled > 0 {
        // Past the ends were filled where asked, or by the input's default where any was.
        let ends_filled = args.fill.extrapolate.unwrap_or(c.extrapolated > 0);
        let why = match (args.fill.max_gap, ends_filled) {
            (Some(_), false) => {
                "past --max-gap, or past a track's ends (--extrapolate fills those)"
            }
            (Some(_), true) => "past --max-gap",
            (None, _) => "past a track's ends (--extrapolate fills those)",
        };
        eprintln!("  {} entries left unfilled: {why}", c.unfilled);
    }
    if c.fits > 1 {
        let how = if c.fits == 2 { "mean" } else { "median" };
        eprintln!(
            "  each entry the {how} of {} fits' fills; the weights below are the first's",
            c.fits
        );
    }
    print_blend(&c.blend);
    if let Some(path) = &args.blend {
        crate::io::save_json(&c.blend, path)?;
    }
    Ok(())
}

/// The weights that `b` filled with, per class of gap, its leans and the field's share.
fn print_blend(b: &crate::gaps::blend::Blend) {
    // One filler alone, or the blend's weights.
    let weights = |w: &crate::gaps::blend::Weights, count: usize| {
        if w.0.contains(&1.0) {
            format!(": {} alone ({count} validation entries)", alone(w))
        } else {
            format!(" (weights from {count} validation entries): {}", listed(w))
        }
    };
    for (k, name) in ["short", "long"].iter().enumerate() {
        let w = if k == 0 { &b.short } else { &b.long };
        match b.validated[k] {
            0 => eprintln!("  {name} gaps: the field's fill (nothing to validate)"),
            count => eprintln!("  {name} gaps{}{}", weights(w, count), held(&b.held_out[k])),
        }
    }
    let mut shortest = crate::gaps::SPLINE_CARRY_FRAMES + 1;
    for class in b.by_length.iter() {
        let lengths = match class.longest {
            Some(l) => format!("{shortest}–{l} frames"),
            None => format!("{shortest} frames or more"),
        };
        shortest = class.longest.map_or(shortest, |l| l + 1);
        let count = class.validated;
        let judged = held(&class.held_out);
        if class.own {
            eprintln!(
                "    gaps of {lengths}{}{judged}",
                weights(&class.weights, count)
            );
        } else {
            eprintln!(
                "    gaps of {lengths}: the long gaps' weights ({count} validation entries){judged}"
            );
        }
    }
    if !b.leans.is_empty() {
        let mut toward: Vec<(&'static str, usize)> = Vec::new();
        for lean in &b.leans {
            let name = alone(&lean.toward);
            match toward.iter_mut().find(|(n, _)| *n == name) {
                Some((_, count)) => *count += 1,
                None => toward.push((name, 1)),
            }
        }
        let listed: Vec<String> = toward.iter().map(|(n, c)| format!("{n} {c}")).collect();
        eprintln!(
            "  {} leans of a track's weight, for its short or its longer gaps, toward one \
             filler, learned on its own validation spans: {}",
            b.leans.len(),
            listed.join(", ")
        );
    }
    if let Some(ends) = &b.ends {
        eprintln!(
            "  beyond a track's ends{}",
            weights(&ends.weights, ends.validated)
        );
    }
    if b.validated != [0, 0] {
        match b.field_validated {
            0 => eprintln!(
                "  the field's fills: not weighed (the fit saw every observation; a fit \
                 without `--blind-validation=false` hides some to weigh them on)"
            ),
            count => {
                eprintln!("  the field's fills weighed on {count} entries hidden from the fit")
            }
        }
    }
}

/// A class's held-out figures, as `; held out: 4.85 (pattern alone 3.95)`, in the units
/// the blend carries (the data's, from a run); nothing where there are none.
fn held(h: &Option<crate::gaps::blend::HeldOut>) -> String {
    h.map_or(String::new(), |h| {
        format!(
            "; held out: {} ({} alone {})",
            significant(h.chosen),
            h.best.label(),
            significant(h.best_alone)
        )
    })
}

/// `v` to three significant figures, without an exponent for the sizes fills have.
fn significant(v: f64) -> String {
    let digits = if v == 0.0 || !v.is_finite() {
        0
    } else {
        (2 - v.abs().log10().floor() as i32).clamp(0, 9) as usize
    };
    format!("{v:.digits$}")
}

/// The label of the filler that holds the most weight (all of it, where it fills alone).
fn alone(w: &crate::gaps::blend::Weights) -> &'static str {
    Filler::ALL
        .into_iter()
        .max_by(|&x, &y| w[x].total_cmp(&w[y]).then(y.cmp(&x)))
        .map_or("the field's fill", |f| f.label())
}

/// The fillers with a weight that prints (0.005 or more), as `label weight`, in order.
fn listed(w: &crate::gaps::blend::Weights) -> String {
    let weights: Vec<String> = w
        .iter()
        .filter(|(_, v)| *v >= 0.005)
        .map(|(f, v)| format!("{} {v:.2}", f.label()))
        .collect();
    weights.join(", ")
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// The held-out figures print to three significant figures, in the data's units.
    #[test]
    fn a_class_s_held_out_figures_print_to_three_significant_figures() {
        assert_eq!(super::significant(12.345), "12.3");
        assert_eq!(super::significant(0.015234), "0.0152");
        assert_eq!(super::significant(7.0), "7.00");
        assert_eq!(super::significant(1234.4), "1234");
        assert_eq!(super::significant(0.0), "0");
        let held = crate::gaps::blend::HeldOut {
            chosen: 4.849,
            best: crate::gaps::Filler::Pattern,
            best_alone: 3.951,
            spans: 20.0,
        };
        assert_eq!(
            super::held(&Some(held)),
            "; held out: 4.85 (pattern alone 3.95)"
        );
        assert_eq!(super::held(&None), "");
    }

    /// `--method` offers every filler there is, by its command-line name, and reads the
    /// report name too.
    #[test]
    fn the_help_lists_every_filler() {
        for command in [
            super::CompleteArgs::command(),
            crate::cli::fill::FillArgs::command(),
        ] {
            let method = command
                .get_arguments()
                .find(|a| a.get_id() == "method")
                .expect("--method");
            let offered: Vec<String> = method
                .get_possible_values()
                .iter()
                .map(|v| v.get_name().to_string())
                .collect();
            let all: Vec<&str> = crate::gaps::Filler::ALL.iter().map(|f| f.flag()).collect();
            assert_eq!(offered, all, "{}", command.get_name());
            for f in crate::gaps::Filler::ALL {
                let value = method
                    .get_possible_values()
                    .into_iter()
                    .find(|v| v.matches(f.name(), false));
                assert!(
                    value.is_some(),
                    "{} does not read {}",
                    command.get_name(),
                    f.name()
                );
            }
        }
    }
}
