//! What the loop does between iterations besides fitting: observation (learning curves),
//! checkpoints and interrupts.

use std::sync::atomic::AtomicBool;

use super::record::{IterationRecord, TrainerSnapshot};
use crate::Result;

/// What [`Trainer::run_with`] does between iterations besides fitting.
type ObserveFn<'a, M> = Box<dyn FnMut(&IterationRecord, M) -> Result<()> + 'a>;
type CheckpointFn<'a> = Box<dyn FnMut(&TrainerSnapshot) -> Result<()> + 'a>;
/// Called after every iteration with its record and the schedule's iteration count.
pub type EachFn<'a> = Box<dyn FnMut(&IterationRecord, usize) -> Result<()> + 'a>;

/// How a fit shows its progress.
pub enum Progress<'a> {
    /// Nothing.
    Off,
    /// A bar on a terminal; where stderr is not one (a log, a pipe), a plain line every
    /// tenth of the fit.
    Shown,
    /// `each(record, iterations)` after every iteration, nothing printed (the Python
    /// package's `progress=` callable).
    Each(EachFn<'a>),
}

impl Progress<'_> {
    /// The same progress for one fit of several in turn, `Each`'s callable borrowed.
    pub fn by_ref(&mut self) -> Progress<'_> {
        match self {
            Progress::Off => Progress::Off,
            Progress::Shown => Progress::Shown,
            Progress::Each(each) => Progress::Each(Box::new(|record, n| each(record, n))),
        }
    }
}

impl From<bool> for Progress<'_> {
    fn from(shown: bool) -> Self {
        if shown {
            Progress::Shown
        } else {
            Progress::Off
        }
    }
}

/// Hooks of a run: observation, checkpoints and interrupts.
pub struct Hooks<'a, M> {
    pub(super) observe: Option<(usize, ObserveFn<'a, M>)>,
    pub(super) checkpoint: Option<(usize, CheckpointFn<'a>)>,
    pub(super) interrupt: Option<&'a AtomicBool>,
    pub(super) stop_after: Option<usize>,
    pub(super) each: Option<EachFn<'a>>,
}

impl<M> Default for Hooks<'_, M> {
    fn default() -> Self {
        Hooks {
            observe: None,
            checkpoint: None,
            interrupt: None,
            stop_after: None,
            each: None,
        }
    }
}

impl<'a, M> Hooks<'a, M> {
    /// No hooks.
    pub fn new() -> Self {
        Self::default()
    }

    /// Calls `observe(record, field)` after every `every`-th iteration and after the last,
    /// with a validation copy of the field (learning curves); `every = 0` never calls it.
    pub fn observe(
        mut self,
        every: usize,
        observe: impl FnMut(&IterationRecord, M) -> Result<()> + 'a,
    ) -> Self {
        if every > 0 {
            self.observe = Some((every, Box::new(observe)));
        }
        self
    }

    /// Calls `save(snapshot)` after every `every`-th iteration, after the last, and when
    /// interrupted.
    pub fn checkpoint(
        mut self,
        every: usize,
        save: impl FnMut(&TrainerSnapshot) -> Result<()> + 'a,
    ) -> Self {
        self.checkpoint = Some((every.max(1), Box::new(save)));
        self
    }

    /// Stops after the iteration during which `flag` was set (e.g. by Ctrl-C).
    pub fn interrupt(mut self, flag: &'a AtomicBool) -> Self {
        self.interrupt = Some(flag);
        self
    }

    /// Calls `each(record, iterations)` after every iteration, before an interrupt is
    /// looked at (so that `each` may set it and stop the fit there).
    pub fn each(mut self, each: EachFn<'a>) -> Self {
        self.each = Some(each);
        self
    }

    /// Stops after `iterations` iterations in all (tests simulate an interrupt with it).
    pub fn stop_after(mut self, iterations: usize) -> Self {
        self.stop_after = Some(iterations);
        self
    }
}
