//! The `doma` command line, one module per subcommand, with the flags that several share
//! in `args.rs`. Each module holds its clap arguments, the mapping from flags to a library
//! job, and the printing; the work is in [`crate::experiments`] and [`crate::run`]. It
//! lives in the library so that the binary stays a `main` and the tests can parse flags.

pub mod batch;
pub mod bench;
pub mod complete;
pub mod eval;
pub mod export;
pub mod fill;
pub mod fit;
pub mod fluid;
pub mod image2d;
pub mod info;
pub mod interrupt;
pub mod mesh_alignment;
pub mod novel_points;
pub mod plot;
pub mod synthetic;
pub mod view;
pub mod warp;

mod args;

pub use args::*;

use clap::{Parser, Subcommand};

use crate::Result;

/// DOMA motion fields (CVPR 2024) on Burn: fit SIREN motion fields to point trajectories.
#[derive(Parser, Debug)]
#[command(name = "doma", version, about)]
pub struct Cli {
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Fit the synthetic benchmark (paper Tab. 2) and print the EPE table.
    Synthetic(synthetic::SyntheticArgs),
    /// Time the Jacobian step and the training step per backend and Jacobian method.
    Bench(bench::BenchArgs),
    /// Fit 25 % of an animated mesh's vertices, predict the rest (paper Tab. 1): EPE, CD, CDN.
    NovelPoints(novel_points::NovelPointsArgs),
    /// Align the frame-0 template to every frame with guidance keypoints (paper Tab. 3).
    MeshAlignment(mesh_alignment::MeshAlignmentArgs),
    /// DPF vs Trans vs Affinity on 10-frame clips of a fluid simulation (supplement Tab. A8).
    Fluid(fluid::FluidArgs),
    /// Trans vs Affinity on a deforming 2-D pixel grid at widths 32/64/128 (supplement Tab. A7).
    Image2d(image2d::Image2dArgs),
    /// Fit a motion field to your own data into a run folder (resumable).
    Fit(fit::FitArgs),
    /// Fit every sequence of a manifest (or one shard of them) into run folders.
    Batch(batch::BatchArgs),
    /// Print the metrics of a fitted run, on its held-out points or on new data.
    Eval(eval::EvalArgs),
    /// Write every track of a fitted run at every frame, gaps filled by the field.
    Complete(complete::CompleteArgs),
    /// Fill the gaps of recordings (files or folders of .c3d and .trc) in one go.
    Fill(fill::FillArgs),
    /// Warp a canonical mesh through a fitted run and write an OBJ sequence.
    Warp(warp::WarpArgs),
    /// Export a fitted run's motion as an animated binary glTF (.glb).
    Export(export::ExportArgs),
    /// Write a self-contained HTML page that plays a fitted run in WebGL.
    View(view::ViewArgs),
    /// Print a run's model, parameter count, checkpoint size and data shape.
    Info(info::InfoArgs),
    /// Write plots of a run (loss, per-frame EPE, the longest filled gaps, 3-view error scatters) to RUN/plots/, PNG and SVG.
    Plot(plot::PlotArgs),
}

impl Command {
    /// Runs the subcommand.
    pub fn run(self) -> Result<()> {
        match self {
            Command::Synthetic(a) => synthetic::run(&a),
            Command::Bench(a) => bench::run(&a),
            Command::NovelPoints(a) => novel_points::run(&a),
            Command::MeshAlignment(a) => mesh_alignment::run(&a),
            Command::Fluid(a) => fluid::run(&a),
            Command::Image2d(a) => image2d::run(&a),
            Command::Fit(a) => fit::run(&a),
            Command::Batch(a) => batch::run(&a),
            Command::Eval(a) => eval::run(&a),
            Command::Warp(a) => warp::run(&a),
            Command::Export(a) => export::run(&a),
            Command::Complete(a) => complete::run(&a),
            Command::Fill(a) => fill::run(&a),
            Command::View(a) => view::run(&a),
            Command::Info(a) => info::run(&a),
            Command::Plot(a) => plot::run(&a),
        }
    }
}

/// Sets up the process for the CLI (and any program that fits): glibc's allocator for training
/// loops, the default signal disposition on a closed pipe (`doma eval RUN | head` exits
/// quietly, as Unix tools do), and Burn's default device ([`crate::backend::pin_default_device`]).
///
/// # Safety
/// Call it first in `main`, before any other thread exists (it sets an environment
/// variable and a signal disposition).
pub unsafe fn init_process() {
    crate::backend::tune_allocator();
    // SAFETY: restoring the default disposition of a signal; the caller guarantees that
    // no other thread exists yet.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        crate::backend::pin_default_device();
    }
}

/// The `doma` command line on `args` (the program name first): parses them (a bad flag
/// or `--help` prints clap's message) and runs the command, printing an error as
/// `error: …` (an internal error too: a panic left in the code is caught and reported as
/// one line naming the command). Returns the exit status: 0, 1 for an error, clap's for a
/// bad flag. The
/// binary and the Python package's console script both run it.
pub fn run_args<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    use clap::Parser;
    let args: Vec<std::ffi::OsString> = args.into_iter().map(Into::into).collect();
    let line: Vec<String> = args
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return e.exit_code();
        }
    };
    match crate::error::catch_internal_errors(move || cli.command.run()) {
        Ok(Ok(())) => 0,
        Ok(Err(e)) => {
            eprintln!("error: {e:#}");
            1
        }
        Err(what) => {
            eprintln!(
                "error: doma stopped on an internal error ({what}) while running `{}`; this \
                 is a bug, please report it with that command line (RUST_BACKTRACE=1 shows \
                 where)",
                line.join(" ")
            );
            1
        }
    }
}
