//! The fillers that doma's fill blends and is measured against ([`Filler`], one variant
//! each), what they fill from ([`Sources`]), and one value per filler ([`PerFiller`], a
//! blend's weights or a report's errors, keyed by name in JSON).
//!
//! The classic fillers are in [`super::classic`], the field's fills in
//! [`super::field_fill`]. Every filler sees only the observed entries (docs/design.md §7).

use std::cell::{OnceCell, RefCell};
use std::ops::{Index, IndexMut};
use std::sync::OnceLock;

use serde::de::{Deserializer, IgnoredAny, MapAccess, Visitor};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};

use super::field_fill::{Lending, carry_residuals, field_fill_from_carry};
use super::marked::Marked;
use super::prediction::FieldPrediction;

/// Defines [`Filler`] and its [`Filler::ALL`] and [`Filler::COUNT`] from one list of
/// variants, so that a filler added to the enum is in both.
macro_rules! fillers {
    ($($(#[$doc:meta])* $variant:ident,)*) => {
        /// A gap filler: one variant and one arm of [`Filler::fill_at`] each. Reports, `doma
        /// complete`'s printout and the blend's weights list them by [`Filler::name`]; the
        /// command line by [`Filler::flag`].
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Filler {
            $($(#[$doc])* $variant,)*
        }

        impl Filler {
            /// The number of fillers.
            pub const COUNT: usize = [$(Filler::$variant),*].len();

            /// Every filler, in the order of a blend's weights: a tie in the blend goes to
            /// the earlier (the field's fill first).
            pub const ALL: [Filler; Filler::COUNT] = [$(Filler::$variant),*];
        }
    };
}

fillers! {
    /// The field's fill: the field corrected by its neighbours' and the track's own
    /// residuals ([`super::field_fill::field_fill`], [`Lending::Fixed`]).
    FieldFill,
    /// Each track's natural cubic spline ([`Marked::spline`]).
    Spline,
    /// The neighbours' motion ([`Marked::neighbours`]).
    Neighbours,
    /// The iterative PCA fill ([`Marked::iterative_pca`]).
    IterativePca,
    /// Each track's linear interpolation ([`Marked::linear`]).
    Linear,
    /// The field's fill with lenders chosen frame by frame among the tracks seen there
    /// ([`Lending::FrameByFrame`]).
    FieldFillFramewise,
    /// Vicon Nexus's pattern fill: one donor's motion ([`Marked::pattern`]).
    Pattern,
    /// Vicon Nexus's rigid-body fill: three donors' rigid motion ([`Marked::rigid_body`]).
    RigidBody,
    /// Burke & Lasenby's low-dimensional Kalman smoother ([`Marked::kalman`]; the linear
    /// fill where it cannot run).
    Kalman,
    /// Gløersen & Federolf's PCA fill, strategy R2 ([`Marked::gloersen`]; the linear fill
    /// where it cannot run).
    Gloersen,
    /// The rigid-body fill from the three donors that best carry the track through its
    /// own observations around the gap ([`Marked::segment`]).
    Segment,
    /// The rigid-body fill with its donors passed on where they are lost, for gaps that
    /// no three markers are seen through ([`Marked::chain`]).
    Chain,
    /// Qualisys's relational fill: the track's coordinates in three donors' frame,
    /// interpolated across the gap ([`Marked::relational`]).
    Relational,
    /// The chain fill plus the field's motion away from what the chain fill makes of the
    /// field itself: what the donors' rigid transport cannot see, from the field
    /// ([`Sources::field_beside`]).
    FieldChain,
    /// The same beside the segment fill ([`Sources::field_beside`]).
    FieldSegment,
}

impl Filler {
    /// Its place in [`Filler::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its key in reports and weights.
    pub fn name(self) -> &'static str {
        match self {
            Filler::FieldFill => "field_fill",
            Filler::Spline => "spline",
            Filler::Neighbours => "neighbours",
            Filler::IterativePca => "iterative_pca",
            Filler::Linear => "linear",
            Filler::FieldFillFramewise => "field_fill_framewise",
            Filler::Pattern => "pattern",
            Filler::RigidBody => "rigid_body",
            Filler::Kalman => "kalman",
            Filler::Gloersen => "gloersen",
            Filler::Segment => "segment",
            Filler::Chain => "chain",
            Filler::Relational => "relational",
            Filler::FieldChain => "field_chain",
            Filler::FieldSegment => "field_segment",
        }
    }

    /// Its name for people.
    pub fn label(self) -> &'static str {
        match self {
            Filler::FieldFill => "field's fill",
            Filler::Spline => "spline",
            Filler::Neighbours => "neighbours",
            Filler::IterativePca => "iterative PCA",
            Filler::Linear => "linear",
            Filler::FieldFillFramewise => "field's fill, lenders frame by frame",
            Filler::Pattern => "pattern",
            Filler::RigidBody => "rigid body",
            Filler::Kalman => "Kalman smoother",
            Filler::Gloersen => "Gløersen PCA",
            Filler::Segment => "segment (rigid body, donors judged)",
            Filler::Chain => "chain (rigid body, donors passed on)",
            Filler::Relational => "relational (Qualisys)",
            Filler::FieldChain => "field beside the chain fill",
            Filler::FieldSegment => "field beside the segment fill",
        }
    }

    /// Its name on the command line: [`Filler::name`] in kebab case, as every other value
    /// there is (`rigid-body`).
    pub fn flag(self) -> &'static str {
        static FLAGS: OnceLock<[&'static str; Filler::COUNT]> = OnceLock::new();
        FLAGS.get_or_init(|| {
            Filler::ALL.map(|f| &*Box::leak(f.name().replace('_', "-").into_boxed_str()))
        })[self.index()]
    }

    /// The keys that reports written before today's names used for it.
    pub fn former_names(self) -> &'static [&'static str] {
        match self {
            Filler::FieldFill => &["carried"],
            Filler::FieldFillFramewise => &["framewise"],
            Filler::IterativePca => &["low_rank"],
            _ => &[],
        }
    }

    /// The filler named `name`: its [`Filler::name`] or [`Filler::flag`], or a key reports
    /// written before these names used ([`Filler::former_names`]).
    pub fn from_name(name: &str) -> Option<Filler> {
        let name = name.replace('-', "_");
        Filler::ALL
            .into_iter()
            .find(|f| f.name() == name || f.former_names().contains(&name.as_str()))
    }

    /// The filler named `name` ([`Filler::from_name`]), or a message listing the names.
    pub fn parse(name: &str) -> Result<Filler, String> {
        Filler::from_name(name).ok_or_else(|| {
            let names: Vec<&str> = Filler::ALL.iter().map(|f| f.flag()).collect();
            format!("`{name}` is not a filler: {}", names.join(", "))
        })
    }

    /// Its bit in a set of fillers (`1 << index`).
    pub fn bit(self) -> u32 {
        1 << self.index()
    }

    /// Whether it is one of the field's fills (the others are the classic fillers).
    pub fn is_field(self) -> bool {
        Filler::FIELD.contains(&self)
    }

    /// The field's fills, in the order of [`Filler::ALL`]: what stage 2 of a blend weighs
    /// against the classic fillers' blend.
    pub const FIELD: [Filler; 4] = [
        Filler::FieldFill,
        Filler::FieldFillFramewise,
        Filler::FieldChain,
        Filler::FieldSegment,
    ];

    /// This filler's value at each of `entries` `(frame, track)`, filled from the
    /// observations of `sources`. An entry of a track never observed is whatever the
    /// positions hold there (NaN for the neighbours' motion).
    pub fn fill_at(self, sources: &Sources, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        match (sources.observed_fill(self, entries), self) {
            (Some(values), _) => values,
            (None, Filler::FieldChain) => sources.field_beside(Filler::Chain, entries),
            (None, Filler::FieldSegment) => sources.field_beside(Filler::Segment, entries),
            (None, _) => {
                let lending = match self {
                    Filler::FieldFillFramewise => Lending::FrameByFrame,
                    _ => Lending::Fixed,
                };
                pick(&sources.field_fill(lending), entries, sources.marked.points)
            }
        }
    }

    /// This filler's value at each of `entries` from the observations of `marked` alone;
    /// `None` for the field's fills, which need a field.
    pub fn fill_observed(
        self,
        marked: &Marked,
        entries: &[(usize, usize)],
    ) -> Option<Vec<[f32; 3]>> {
        let whole = match self {
            Filler::FieldFill
            | Filler::FieldFillFramewise
            | Filler::FieldChain
            | Filler::FieldSegment => return None,
            Filler::Spline => marked.spline(),
            Filler::IterativePca => marked.iterative_pca(),
            Filler::Kalman => marked.kalman().unwrap_or_else(|| marked.linear()),
            Filler::Gloersen => marked.gloersen().unwrap_or_else(|| marked.linear()),
            Filler::Linear => marked.linear(),
            Filler::Neighbours => return Some(marked.neighbours(entries)),
            Filler::Pattern => return Some(marked.pattern(entries)),
            Filler::RigidBody => return Some(marked.rigid_body(entries)),
            Filler::Segment => return Some(marked.segment(entries)),
            Filler::Chain => return Some(marked.chain(entries)),
            Filler::Relational => return Some(marked.relational(entries)),
        };
        Some(pick(&whole, entries, marked.points))
    }
}

/// The values of `whole` (`[T, N, 3]`) at `entries`.
fn pick(whole: &[f32], entries: &[(usize, usize)], n: usize) -> Vec<[f32; 3]> {
    entries
        .iter()
        .map(|&(k, i)| {
            let e = 3 * (k * n + i);
            [whole[e], whole[e + 1], whole[e + 2]]
        })
        .collect()
}

/// A donor filler's values and the entries they were asked at.
type DonorFill = (Filler, Vec<(usize, usize)>, Vec<[f32; 3]>);

/// What every filler fills from: the masked tracks and the field's prediction of them, with
/// the residual carry that both field's fills start from computed once.
pub struct Sources<'a> {
    /// The tracks and the observations to fill from.
    pub marked: Marked<'a>,
    /// The field's prediction of the tracks.
    pub field: &'a FieldPrediction<'a>,
    carried: OnceCell<Vec<f32>>,
    /// The chain and segment fills of the observations, with the entries they were asked
    /// at: the field's fills beside them ([`Sources::field_beside`]) read them again.
    donor_fills: RefCell<Vec<DonorFill>>,
}

impl<'a> Sources<'a> {
    /// The sources of `marked` and `field`.
    pub fn new(marked: Marked<'a>, field: &'a FieldPrediction<'a>) -> Self {
        Sources {
            marked,
            field,
            carried: OnceCell::new(),
            donor_fills: RefCell::new(Vec::new()),
        }
    }

    /// [`Filler::fill_observed`] of the observations, computed once per filler and entries
    /// for the donors the field's fills stand beside.
    fn observed_fill(&self, filler: Filler, entries: &[(usize, usize)]) -> Option<Vec<[f32; 3]>> {
        if !matches!(filler, Filler::Chain | Filler::Segment) {
            return filler.fill_observed(&self.marked, entries);
        }
        let cached = self
            .donor_fills
            .borrow()
            .iter()
            .find_map(|(f, at, values)| {
                (*f == filler && at.as_slice() == entries).then(|| values.clone())
            });
        if cached.is_some() {
            return cached;
        }
        let values = filler.fill_observed(&self.marked, entries)?;
        let entry = (filler, entries.to_vec(), values.clone());
        self.donor_fills.borrow_mut().push(entry);
        Some(values)
    }

    /// `donor`'s fill of the tracks at `entries` plus the field's motion away from what
    /// `donor` makes of the field's own prediction under the same mask: `d(y) + (f − d(f))`,
    /// the donors' transport of the observations corrected by what the field says the
    /// transport misses (skin sliding, joints bending inside the gap). Where the field is
    /// exact it is the field; where the field moves as rigidly as the donors, it is `donor`.
    pub fn field_beside(&self, donor: Filler, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        let predicted = self.field.predicted();
        if predicted.len() != self.marked.positions.len() {
            // No prediction of these tracks: no value, as a filler that cannot run.
            return vec![[f32::NAN; 3]; entries.len()];
        }
        let of_field = Marked::new(
            self.marked.frames,
            self.marked.points,
            predicted,
            self.marked.observed,
        );
        let (y, f) = (
            self.observed_fill(donor, entries),
            donor.fill_observed(&of_field, entries),
        );
        let (Some(y), Some(f)) = (y, f) else {
            return vec![[f32::NAN; 3]; entries.len()];
        };
        let n = self.marked.points;
        entries
            .iter()
            .zip(y.iter().zip(&f))
            .map(|(&(k, i), (y, f))| {
                let e = 3 * (k * n + i);
                std::array::from_fn(|c| y[c] + (predicted[e + c] - f[c]))
            })
            .collect()
    }

    /// The field's fill of every gap with `lending`.
    pub fn field_fill(&self, lending: Lending) -> Vec<f32> {
        let carried = self
            .carried
            .get_or_init(|| carry_residuals(&self.marked, self.field.predicted()));
        field_fill_from_carry(&self.marked, self.field, carried, lending)
    }
}

/// One value per [`Filler`], indexed by it; in JSON an object keyed by [`Filler::name`]
/// (earlier reports' keys are read too, a key for no filler is passed over).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerFiller<T>(pub [T; Filler::COUNT]);

/// A value of a [`PerFiller`]: what a key missing from the JSON reads as, and whether a
/// value is left out when written.
pub trait FillerValue: Copy {
    /// The value of a missing key.
    const ABSENT: Self;
    /// Whether the value is left out of the JSON.
    fn is_absent(&self) -> bool;
}

/// A weight: a missing one is 0, every one is written.
impl FillerValue for f64 {
    const ABSENT: f64 = 0.0;
    fn is_absent(&self) -> bool {
        false
    }
}

/// A measure that a report may lack (one written before that filler existed).
impl FillerValue for Option<f64> {
    const ABSENT: Option<f64> = None;
    fn is_absent(&self) -> bool {
        self.is_none()
    }
}

impl<T> Index<Filler> for PerFiller<T> {
    type Output = T;
    fn index(&self, f: Filler) -> &T {
        &self.0[f.index()]
    }
}

impl<T> IndexMut<Filler> for PerFiller<T> {
    fn index_mut(&mut self, f: Filler) -> &mut T {
        &mut self.0[f.index()]
    }
}

impl<T: FillerValue> PerFiller<T> {
    /// `f(filler)` for every filler.
    pub fn from_fn(f: impl FnMut(Filler) -> T) -> Self {
        PerFiller(Filler::ALL.map(f))
    }

    /// Every filler with its value, in the order of [`Filler::ALL`].
    pub fn iter(&self) -> impl Iterator<Item = (Filler, T)> + '_ {
        Filler::ALL.into_iter().map(|f| (f, self[f]))
    }
}

impl Serialize for Filler {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Filler {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        Filler::from_name(&name)
            .ok_or_else(|| serde::de::Error::custom(format!("no filler named {name:?}")))
    }
}

impl<T: FillerValue + Serialize> Serialize for PerFiller<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let present: Vec<(Filler, T)> = self.iter().filter(|(_, v)| !v.is_absent()).collect();
        let mut map = s.serialize_map(Some(present.len()))?;
        for (f, v) in present {
            map.serialize_entry(f.name(), &v)?;
        }
        map.end()
    }
}

impl<'de, T: FillerValue + Deserialize<'de>> Deserialize<'de> for PerFiller<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct ByName<T>(std::marker::PhantomData<T>);
        impl<'de, T: FillerValue + Deserialize<'de>> Visitor<'de> for ByName<T> {
            type Value = PerFiller<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object keyed by filler names")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut out = PerFiller([T::ABSENT; Filler::COUNT]);
                while let Some(key) = map.next_key::<String>()? {
                    match Filler::from_name(&key) {
                        Some(f) => out[f] = map.next_value()?,
                        None => {
                            map.next_value::<IgnoredAny>()?;
                        }
                    }
                }
                Ok(out)
            }
        }
        d.deserialize_map(ByName(std::marker::PhantomData))
    }
}

/// The largest Euclidean error of `fill` against `truth` (both `[T, N, 3]`) over track
/// `i`'s entries at `frames`: how a test reads one hidden marker's fill.
#[cfg(test)]
pub(super) fn worst_error(
    fill: &[f32],
    truth: &[f32],
    n: usize,
    i: usize,
    frames: std::ops::Range<usize>,
) -> f32 {
    frames
        .map(|k| {
            let e = 3 * (k * n + i);
            (0..3)
                .map(|c| (fill[e + c] - truth[e + c]).powi(2))
                .sum::<f32>()
                .sqrt()
        })
        .fold(0f32, f32::max)
}

#[cfg(test)]
mod tests;
