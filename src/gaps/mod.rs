//! Gap filling: every unobserved entry of a set of tracks, by the fitted field and by the
//! fillers of the motion-capture gap-filling literature. Numbers in, numbers out: nothing
//! here touches a model, a tensor or the trainer; `run/complete/` and
//! `run/gap_report.rs` evaluate the field and pass its prediction in (for a long
//! recording, a function that predicts the frames a window asks for:
//! [`FieldPrediction::on_demand`]).
//!
//! # The words
//!
//! - A **gap** ([`spans::Gap`]) is a run of frames in which a track is unobserved. It is
//!   *interior* with an observation on both sides, *long* past [`SPLINE_CARRY_FRAMES`]
//!   frames; long gaps fall in classes by length ([`blend::length_class`]).
//! - A **span** is a run of observations hidden on purpose: to measure a fill
//!   ([`spans::hold_out_spans`], `--holdout-observations`) or to validate a blend
//!   ([`spans::validation_spans`]).
//! - A **filler** ([`Filler`]) fills every gap from the observations alone: the classic
//!   ones (linear, spline, the neighbours' motion, iterative PCA), capture software's that
//!   borrow *donor* markers' motion (pattern and rigid-body fill), Burke & Lasenby's
//!   Kalman smoother, Gløersen & Federolf's PCA fill, the rigid-body fill with its donors
//!   judged on the track's own observations (the *segment* fill) or passed on through
//!   the gap (the *chain* fill), and the field's two.
//! - The **field's fill** ([`field_fill::field_fill`]) is the field's prediction corrected
//!   by the residual of the track's nearest tracks at that frame (its *lenders*), then by
//!   the track's own residual carried across the gap ([`field_fill::carry_residuals`],
//!   *the carry*).
//! - **doma's fill** ([`blend::blended_fill`], what `doma complete` writes) is the blend of
//!   every filler, the field's fill and the classic ones, by weights validated on the data's
//!   own observations, used only where it beats the field's fill cross-fitted.
//!
//! Every function takes the tracks as one view, [`Marked`]: `positions` `[T, N, 3]` and
//! `observed` `[T, N]`, frame-major, so that a window of frames is a view too
//! ([`Marked::window`]): past [`window::WINDOW_ENTRIES`] entries the fillers run on windows
//! of time, and what a fill holds beyond the data does not grow with the recording. Only observed entries are read, so what an unobserved
//! entry holds (NaN, zeros) never matters; a track never observed is left as it is.
//!
//! # The files
//!
//! | file | holds |
//! |---|---|
//! | `fillers.rs` | [`Marked`], [`Filler`] (one variant and one arm each), [`Sources`], [`PerFiller`] |
//! | `classic.rs` | linear, spline, the neighbours' motion, iterative PCA: methods of [`Marked`] |
//! | `kalman.rs` | Burke & Lasenby's Kalman smoother: a method of [`Marked`] |
//! | `gloersen.rs` | Gløersen & Federolf's PCA fill (R2): a method of [`Marked`] |
//! | `donors.rs` | pattern and rigid-body fill: methods of [`Marked`] |
//! | `segment.rs` | the segment fill: rigid-body fill from the donors that carry the track best around its gap |
//! | `chain.rs` | the chained rigid-body fill: donors passed on through a gap that no three markers are seen through |
//! | `field_fill.rs` | the field's fill: the lenders ([`Lending`]), the residual carry |
//! | `prediction.rs` | [`FieldPrediction`]: the field's prediction, given or computed window by window |
//! | `blend.rs` | [`blend::Weights`] (one per filler), learning them per class of gap length and applying a blend (tests in `blend/tests.rs`) |
//! | `spans.rs` | gaps and their classes and lengths, hidden and validation spans |
//! | `confidence.rs` | the expected error of a filled gap: the donor fillers' spread, calibrated on hidden spans |
//! | `linalg.rs` | the small solvers: the spline's system, simplex least squares |
//! | `eigen.rs` | eigenproblems (Jacobi, Householder + QL) and principal components |
//! | `window.rs` | long recordings in windows of time: where each gap is filled, each validation draw drawn |
//!
//! Adding a filler: a variant of [`Filler`], its name and label, its arm in
//! [`Filler::fill_at`] (its function in a file of its own or in `classic.rs`), and tests.
//! Reports, the blend and `doma complete`'s printout take it from [`Filler::ALL`]
//! (docs/design.md §7).

pub mod blend;
pub mod chain;
pub mod classic;
pub mod confidence;
pub mod donors;
pub mod eigen;
pub mod field_fill;
pub mod fillers;
pub mod gloersen;
pub mod kalman;
pub mod linalg;
pub mod prediction;
pub mod segment;
pub mod spans;
pub mod window;

pub use field_fill::{Lending, SPLINE_CARRY_FRAMES};
pub use fillers::{Filler, Marked, PerFiller, Sources};
pub use prediction::FieldPrediction;
