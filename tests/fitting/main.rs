//! Fitting: the trainer and its recipes, run folders (resume, eval, locks), guided
//! alignment, the experiments at small sizes, and regulariser weights by validation.

#[path = "../common/mod.rs"]
mod common;

mod alignment;
mod experiments_small;
mod fit;
mod fits;
mod recipe;
mod run;
mod tracks;
mod weight_search;
