//! What both stages of a blend's learning share: a validation entry's errors, one per
//! candidate ([`Residual`]), gathered per [`Pool`]; the objective ([`cost`]) and its
//! minimiser over the simplex ([`mean_distance`]); and the choice between a blend and the
//! best candidate alone, cross-fitted ([`solve`]).
//!
//! The objective is the literature's: the mean Euclidean distance of each gap, averaged
//! over the gaps ([`Residual::weight`]: every validation span counts once, whatever its
//! length). It is minimised by iteratively reweighted least squares ([`mean_distance`]):
//! least squares alone lets a few spans that every filler misses by far set the weights
//! of all of them.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use std::ops::Range;
use std::sync::Arc;

use super::class::Pool;
use super::{M, filler_values};
use crate::gaps::fillers::{Filler, Sources};
use crate::gaps::spans::GapIndex;
use crate::numeric::linalg::simplex_least_squares;

/// The reweighting steps of [`mean_distance`] after its least-squares start.
const REWEIGHTS: usize = 16;

/// The entries [`mean_distance`] solves on, at most: every k-th past that. A minute of
/// capture holds hundreds of thousands per class, each solve builds a Gram matrix of
/// them per step, and a span's neighbouring entries say nearly the same.
const SOLVED_ENTRIES: usize = 1 << 14;

/// One validation entry: each of `K` candidates' error there, `p − y` (in `f32`, as the
/// fills are: a long recording's draws hold millions), the length of its gap and its track.
pub(super) struct Residual<const K: usize> {
    pub(super) errors: [[f32; 3]; K],
    pub(super) len: usize,
    /// The track whose entry it is.
    pub(super) track: usize,
    /// The frames from it to the nearest observation the fillers saw: 1 beside one. A
    /// validation span that runs into a real gap is judged at the gap's border, however
    /// long the gap.
    pub(super) depth: usize,
}

/// A draw's residuals per [`Pool`] (by [`Pool::index`]): a long gap's entry counts in
/// two (its class and the pooled long gaps), held once.
pub(super) type Pools<const K: usize> = [Vec<Arc<Residual<K>>>; Pool::COUNT];

/// One validation draw's hidden entries, `(frame, track)`.
pub(super) type Hidden = Vec<(usize, usize)>;

/// No residual in any pool.
pub(super) fn empty_pools<const K: usize>() -> Pools<K> {
    std::array::from_fn(|_| Vec::new())
}

impl<const K: usize> Residual<K> {
    /// Its weight in the objective: one over the length of its gap, so that each gap
    /// counts once.
    pub(super) fn weight(&self) -> f64 {
        1.0 / self.len.max(1) as f64
    }

    /// The distance of the blend `w` to the truth.
    pub(super) fn distance(&self, w: &[f64; K]) -> f64 {
        // The candidates without weight add nothing: skipped, as most are in a blend and
        // every lean judged on every entry of a minute of capture.
        (0..3)
            .map(|c| {
                (0..K)
                    .filter(|&m| w[m] != 0.0)
                    .map(|m| w[m] * self.errors[m][c] as f64)
                    .sum::<f64>()
                    .powi(2)
            })
            .sum::<f64>()
            .sqrt()
    }
}

/// The objective: `Σ weight · distance` of the blend `w` over `residuals`.
pub(super) fn cost<'a, const K: usize>(
    residuals: impl Iterator<Item = &'a Residual<K>>,
    w: &[f64; K],
) -> f64 {
    residuals.map(|r| r.weight() * r.distance(w)).sum()
}

/// The convex weights, on the candidates whose bits are set in `allowed`, with the least
/// [`cost`] over `all` (at most [`SOLVED_ENTRIES`] of them, evenly spaced): least squares,
/// then [`REWEIGHTS`] steps that weigh each entry by one over its distance (a
/// majorisation of the distance, minimised exactly over the simplex each step, so the
/// cost never rises; the best seen is kept).
fn mean_distance<const K: usize>(all: &[&Residual<K>], allowed: u32) -> [f64; K] {
    let stride = all.len().div_ceil(SOLVED_ENTRIES).max(1);
    let residuals: Vec<&Residual<K>> = all.iter().step_by(stride).copied().collect();
    let gram = |scale: &dyn Fn(&Residual<K>) -> f64| {
        let mut e = [[0f64; K]; K];
        for r in &residuals {
            let s = r.weight() * scale(r);
            for m in 0..K {
                for l in m..K {
                    e[m][l] += s
                        * (0..3)
                            .map(|c| r.errors[m][c] as f64 * r.errors[l][c] as f64)
                            .sum::<f64>();
                }
            }
        }
        for m in 0..K {
            for l in 0..m {
                e[m][l] = e[l][m];
            }
        }
        e
    };
    let mut w = simplex_least_squares(&gram(&|_| 1.0), allowed);
    let mut best = (w, cost(residuals.iter().copied(), &w));
    let total: f64 = residuals.iter().map(|r| r.weight()).sum();
    for _ in 0..REWEIGHTS {
        if best.1 <= 0.0 || total <= 0.0 {
            break;
        }
        // Distances below a thousandth of the mean are held there: an entry filled
        // exactly would otherwise take all the weight.
        let floor = 1e-3 * best.1 / total;
        w = simplex_least_squares(&gram(&|r| 1.0 / r.distance(&w).max(floor)), allowed);
        let c = cost(residuals.iter().copied(), &w);
        if c < best.1 * (1.0 - 1e-9) {
            best = (w, c);
        } else {
            break;
        }
    }
    best.0
}

/// The candidate of `allowed` with the least of `costs`; ties go to the earlier.
fn least<const K: usize>(costs: &[f64; K], allowed: u32) -> Option<usize> {
    (0..K)
        .filter(|&k| allowed & (1 << k) != 0)
        .min_by(|&x, &y| costs[x].total_cmp(&costs[y]).then(x.cmp(&y)))
}

/// The candidate that holds the whole of `w`, if one does.
pub(super) fn single<const K: usize>(w: &[f64; K]) -> Option<usize> {
    (0..K).find(|&k| w[k] == 1.0)
}

/// The whole weight on candidate `k`.
pub(super) fn one_hot<const K: usize>(k: usize) -> [f64; K] {
    std::array::from_fn(|m| if m == k { 1.0 } else { 0.0 })
}

/// What [`solve`] chose for a pool, and what each held-out group of draws said of it.
pub(super) struct Solved<const K: usize> {
    /// The weights chosen.
    pub weights: [f64; K],
    /// Whether the blend beat every candidate alone.
    pub beat: bool,
    /// Per held-out group with entries: the cross-fitted blend's cost there and each
    /// candidate's alone.
    pub groups: Vec<(f64, [f64; K])>,
    /// The group (`draw % groups`) each of `groups` holds out, in its order.
    pub held: Vec<usize>,
    /// The validation spans in the held-out groups: the sum of their entries'
    /// [`Residual::weight`], what turns a cost into a mean distance per span.
    pub spans: f64,
}

impl<const K: usize> Solved<K> {
    /// The cost of the choice on each held-out group: the cross-fitted blend's where the
    /// blend was chosen, the chosen candidate's alone otherwise.
    pub fn chosen_costs(&self) -> Vec<f64> {
        let single = single(&self.weights);
        self.groups
            .iter()
            .map(|(blended, alone)| match (self.beat, single) {
                (false, Some(k)) => alone[k],
                _ => *blended,
            })
            .collect()
    }

    /// The held-out figures of `costs` (one per held-out group, as [`Self::chosen_costs`]
    /// gives them) beside the best of `allowed`'s candidates alone on the same spans;
    /// `None` where no group was held out.
    pub fn held_out(&self, costs: &[f64], allowed: u32) -> Option<(f64, usize, f64)> {
        if self.groups.is_empty() || self.spans <= 0.0 {
            return None;
        }
        let alone: [f64; K] =
            std::array::from_fn(|k| self.groups.iter().map(|(_, a)| a[k]).sum::<f64>());
        let best = least(&alone, allowed)?;
        let chosen: f64 = costs.iter().sum();
        Some((chosen / self.spans, best, alone[best] / self.spans))
    }
}

/// One pool's weights over `draws` (each draw's residuals per pool), on the candidates
/// of `allowed`: the blend with the least mean distance if it beats every allowed
/// candidate alone cross-fitted (draw `d` in group `d % groups`, at most `groups` groups,
/// each judged with the weights of the others), else the candidate that did best alone;
/// and whether the blend won.
pub(super) fn solve<const K: usize>(
    draws: &[Pools<K>],
    pool: Pool,
    allowed: u32,
    groups: usize,
) -> ([f64; K], bool) {
    let s = solve_judged(draws, pool, allowed, groups);
    (s.weights, s.beat)
}

/// [`solve`], with what each held-out group said.
pub(super) fn solve_judged<const K: usize>(
    draws: &[Pools<K>],
    pool: Pool,
    allowed: u32,
    groups: usize,
) -> Solved<K> {
    let groups = draws.len().min(groups);
    let of = |group: Option<usize>, held: bool| grouped(draws, pool, groups, group, held);
    let (mut blended, mut alone) = (0f64, [0f64; K]);
    let (mut per_group, mut held, mut spans) = (Vec::new(), Vec::new(), 0f64);
    for group in 0..groups {
        let (rest, judged) = (of(Some(group), false), of(Some(group), true));
        if rest.is_empty() || judged.is_empty() {
            continue;
        }
        held.push(group);
        spans += judged.iter().map(|r| r.weight()).sum::<f64>();
        let b = cost(judged.iter().copied(), &mean_distance(&rest, allowed));
        let a: [f64; K] = std::array::from_fn(|k| cost(judged.iter().copied(), &one_hot::<K>(k)));
        blended += b;
        for k in 0..K {
            alone[k] += a[k];
        }
        per_group.push((b, a));
    }
    let single = least(&alone, allowed).unwrap_or(0);
    let (weights, beat) = if blended < alone[single] {
        (mean_distance(&of(None, true), allowed), true)
    } else {
        (one_hot::<K>(single), false)
    };
    Solved {
        weights,
        beat,
        groups: per_group,
        held,
        spans,
    }
}

/// The cost on `pool`'s entries of each group of `held` (as [`Solved::held`] numbers them,
/// of `groups` groups) of the weights that `wider` (a pool holding `pool`'s entries and
/// more) learns on the other groups' entries: the cross-fitted cost of taking the wider
/// pool's weights there instead of the pool's own.
pub(super) fn wider_costs<const K: usize>(
    draws: &[Pools<K>],
    pool: Pool,
    wider: Pool,
    allowed: u32,
    groups: usize,
    held: &[usize],
) -> Vec<f64> {
    let groups = draws.len().min(groups);
    held.iter()
        .map(|&g| {
            let w = mean_distance(&grouped(draws, wider, groups, Some(g), false), allowed);
            cost(grouped(draws, pool, groups, Some(g), true).into_iter(), &w)
        })
        .collect()
}

/// `pool`'s entries, draw by draw in order, of the draws in group `group` (draw `d` is in
/// group `d % groups`) where `held`, of the draws in every other group where not; of every
/// draw where `group` is `None`.
fn grouped<const K: usize>(
    draws: &[Pools<K>],
    pool: Pool,
    groups: usize,
    group: Option<usize>,
    held: bool,
) -> Vec<&Residual<K>> {
    draws
        .iter()
        .enumerate()
        .filter(|&(d, _)| group.is_none_or(|g| (d % groups == g) == held))
        .flat_map(|(_, f)| f[pool.index()].iter().map(|r| &**r))
        .collect()
}

/// Every filler's error at `hidden` `(frame, track)`, entries observed in `tracks` that
/// `sources` lacks, filled from the observations of `sources`, each with the length of
/// its gap there and its depth in it: one per entry of `hidden`, in its order, `None`
/// where the entry is no gap there or a filler has no finite value.
pub(super) fn residuals(
    sources: &Sources,
    hidden: &[(usize, usize)],
    fillers: u32,
) -> Vec<Option<Arc<Residual<M>>>> {
    let (positions, n) = (sources.marked.positions, sources.marked.points);
    let index = GapIndex::new(&sources.marked);
    let gaps: Vec<Option<Range<usize>>> = hidden.iter().map(|&(k, i)| index.gap_at(k, i)).collect();
    let entries: Vec<(usize, usize, usize)> = hidden
        .iter()
        .zip(&gaps)
        .filter_map(|(&(k, i), gap)| gap.as_ref().map(|g| (k, i, g.len())))
        .collect();
    let mut filled = filler_values(sources, &entries, fillers)
        .into_iter()
        .zip(&entries);
    hidden
        .iter()
        .zip(gaps)
        .map(|(&(k, i), gap)| {
            let gap = gap?;
            let (p, &(_, _, len)) = filled.next()?;
            let e = 3 * (k * n + i);
            // A filler not computed errs by 0: it takes no weight where it was not asked.
            let errors: [[f32; 3]; M] = std::array::from_fn(|m| {
                let asked = fillers & Filler::ALL[m].bit() != 0;
                std::array::from_fn(|c| {
                    if asked {
                        p[m][c] - positions[e + c]
                    } else {
                        0.0
                    }
                })
            });
            (!errors.iter().flatten().any(|v| !v.is_finite())).then(|| {
                Arc::new(Residual {
                    errors,
                    len,
                    track: i,
                    depth: (k - gap.start + 1).min(gap.end - k),
                })
            })
        })
        .collect()
}

#[cfg(test)]
mod tests;
