//! Gap filling: every unobserved entry of a set of tracks, by the fitted field and by the
//! fillers of the motion-capture gap-filling literature. Numbers in, numbers out: nothing
//! here touches a model, a tensor or the trainer; `run/complete/` and
//! `run/gap_report.rs` evaluate the field and pass its prediction in (for a long
//! recording, a function that predicts the frames a window asks for:
//! [`FieldPrediction::on_demand`]). It imports nothing of doma but the numeric leaf
//! ([`crate::numeric`]); `data/` reads it (the spans a fit hides, the linear stand-in).
//!
//! # The words
//!
//! One word per concept, in code, flags, reports and docs:
//!
//! - A **gap** ([`spans::Gap`]) is a run of frames in which a track is unobserved. It is
//!   *interior* with an observation on both sides. Its **class**
//!   ([`blend::GapClass`]) is *short* (at most [`SPLINE_CARRY_FRAMES`] frames) or one of
//!   the long ones by length; a blend's weights are per class.
//! - A **span** is a run of observations hidden on purpose: to measure a fill
//!   ([`spans::hold_out_spans`], `--holdout-observations`), to validate a blend
//!   ([`spans::validation_spans`]: a **draw** hides one set of them), or hidden from the
//!   fit itself (the **blind spans**, [`blend::blind_spans`]), split into **folds**.
//! - A **filler** ([`Filler`]) fills every gap: the classic ones fill from the
//!   observations alone (linear, spline, the neighbours' motion, iterative PCA, the Kalman
//!   smoother, Gløersen & Federolf's PCA fill), the **donor** fillers move other markers'
//!   motion into the gap (pattern, rigid-body, relational, and doma's segment and chain fills, whose
//!   donors *transport* the track), and the field's two fills read a fitted field.
//! - The **field's fill** ([`field_fill::field_fill`]) is the field's prediction corrected
//!   by the residual of the track's nearest tracks at that frame (its **lenders**), then by
//!   the track's own residual carried across the gap ([`field_fill::carry_residuals`],
//!   **the carry**: the only thing called so).
//! - **doma's fill** ([`blend::doma_fill`], what `doma complete` writes, "doma" in
//!   reports) is every filler weighed by a **blend** ([`blend::Blend`], its weights,
//!   "blend" in reports), validated on the data's own observations.
//! - A **window** is a window of time ([`window`]): past [`window::WINDOW_ENTRIES`]
//!   entries the fillers run on windows, and what a fill holds beyond the data does not
//!   grow with the recording.
//!
//! Every function takes the tracks as one view, [`Marked`] (`marked.rs`, which says why
//! it is not one type with `data::Trajectories` or `data::tracks::Tracks`). Only observed
//! entries are read, so what an unobserved entry holds (NaN, zeros) never matters; a track
//! never observed is left as it is.
//!
//! # The files
//!
//! | file | holds |
//! |---|---|
//! | `marked.rs` | [`Marked`], the view of masked tracks |
//! | `fillers.rs` | [`Filler`] (one variant and one arm each), [`Sources`], [`PerFiller`] |
//! | `classic.rs` | linear, spline, the neighbours' motion: methods of [`Marked`] |
//! | `pca.rs` | the iterative PCA fill, its Gram matrix kept up to date round by round |
//! | `kalman.rs` | Burke & Lasenby's Kalman smoother: a method of [`Marked`] |
//! | `gloersen.rs` | Gløersen & Federolf's PCA fill (R2): a method of [`Marked`] |
//! | `donors.rs` | pattern and rigid-body fill: methods of [`Marked`] |
//! | `segment.rs` | the segment fill: rigid-body fill from the donors that transport the track best around its gap |
//! | `chain.rs` | the chain fill: donors passed on through a gap that no three markers are seen through |
//! | `cluster.rs` | rigid clusters found in the data (a prop, a plate, a head band) and the fill from them |
//! | `relational.rs` | Qualisys's relational fill: the track's coordinates in three donors' frame |
//! | `prediction.rs` | [`FieldPrediction`]: the field's prediction, given or computed window by window, and each track's nearest tracks |
//! | `field_fill.rs` | the field's fill: the lenders ([`Lending`]), the carry |
//! | `spans.rs` | gaps, hidden and validation spans |
//! | `window.rs` | long recordings in windows of time: where each gap is filled, each validation draw drawn |
//! | `blend/` | doma's fill: [`blend::GapClass`], [`blend::Validation`], stage 1, the leans, stage 2 (its `mod.rs` tells the story) |
//! | `confidence.rs` | the expected error of a filled gap: the donor fillers' spread, calibrated on hidden spans |
//!
//! The linear algebra (eigenproblems, the spline's system, least squares on the simplex)
//! and the nearest neighbours are in [`crate::numeric`], shared with the trainer.
//!
//! Adding a filler: a variant of [`Filler`] (its place in [`Filler::ALL`] follows), its
//! name and label, its arm in [`Filler::fill_at`] (its function in a file of its own or in
//! `classic.rs`), a row of docs/usage.md's table (a test holds it), and tests. Reports,
//! the blend, the command line and Python take it from [`Filler::ALL`] (docs/design.md §7).

pub mod blend;
pub mod chain;
pub mod classic;
pub mod cluster;
pub mod confidence;
pub mod donors;
pub mod field_fill;
pub mod fillers;
pub mod gloersen;
pub mod kalman;
pub mod marked;
pub mod pca;
pub mod prediction;
pub mod relational;
pub mod segment;
pub mod spans;
pub mod window;

pub use field_fill::{Lending, SPLINE_CARRY_FRAMES};
pub use fillers::{Filler, PerFiller, Sources};
pub use marked::Marked;
pub use prediction::FieldPrediction;
