//! The classes of gap length that a blend learns its weights by ([`GapClass`]), and the
//! pools of validation entries its weights are solved on ([`Pool`]).

use crate::gaps::SPLINE_CARRY_FRAMES;

/// The classes of long gaps by length: more than [`SPLINE_CARRY_FRAMES`] frames up to
/// twice that, then each up to twice the last, the last one unbounded. A convex blend
/// tuned on two-second gaps is not the one for quarter-second ones: rigid-body fill's
/// error grows with the gap, a spline's much faster, and the squared errors of the longest
/// gaps would set the weights of all of them.
pub const LENGTH_CLASSES: usize = 5;

/// A gap's class by its length: the short gaps (at most [`SPLINE_CARRY_FRAMES`] frames,
/// where the spline carries the field's residual) and [`LENGTH_CLASSES`] classes of the
/// long ones. The one numbering of gap lengths: the strata of the validation spans, a
/// blend's weights ([`super::Blend::weights_for`]) and a track's lean all read it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum GapClass {
    /// At most [`SPLINE_CARRY_FRAMES`] frames.
    Short,
    /// Long gaps of length class `c` (`0..LENGTH_CLASSES`): more than
    /// `SPLINE_CARRY_FRAMES << c` frames, at most twice that (the last class unbounded).
    Long(usize),
}

impl GapClass {
    /// The number of classes: the short gaps and each length class.
    pub const COUNT: usize = 1 + LENGTH_CLASSES;

    /// The class of a gap of `len` frames.
    pub fn of(len: usize) -> GapClass {
        let carry = SPLINE_CARRY_FRAMES;
        if len <= carry {
            return GapClass::Short;
        }
        let (mut class, mut top) = (0, 2 * carry);
        while len > top && class + 1 < LENGTH_CLASSES {
            class += 1;
            top *= 2;
        }
        GapClass::Long(class)
    }

    /// Its place among the [`GapClass::COUNT`] classes: 0 for the short gaps, `c + 1` for
    /// length class `c`.
    pub fn index(self) -> usize {
        match self {
            GapClass::Short => 0,
            GapClass::Long(c) => c + 1,
        }
    }

    /// The class at `index` ([`GapClass::index`]).
    pub fn from_index(index: usize) -> GapClass {
        match index {
            0 => GapClass::Short,
            i => GapClass::Long(i - 1),
        }
    }

    /// Every class, short first.
    pub fn all() -> impl Iterator<Item = GapClass> {
        (0..GapClass::COUNT).map(GapClass::from_index)
    }

    /// Whether it is a class of long gaps.
    pub fn is_long(self) -> bool {
        matches!(self, GapClass::Long(_))
    }

    /// The longest gap of the class, in frames (`None`: no bound).
    pub fn longest(self) -> Option<usize> {
        match self {
            GapClass::Short => Some(SPLINE_CARRY_FRAMES),
            GapClass::Long(c) => (c + 1 < LENGTH_CLASSES).then(|| SPLINE_CARRY_FRAMES << (c + 1)),
        }
    }
}

/// A pool of validation entries that a blend's weights are solved on: one class's, or
/// every long gap's pooled (the weights of a length class with too few entries of its
/// own).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pool {
    /// The entries of one class.
    Class(GapClass),
    /// The entries of every long gap.
    AllLong,
}

impl Pool {
    /// The number of pools: each class and the pooled long gaps.
    pub const COUNT: usize = 1 + GapClass::COUNT;

    /// Its place among the [`Pool::COUNT`] pools: 0 the short gaps, 1 every long gap,
    /// `2 + c` length class `c`.
    pub fn index(self) -> usize {
        match self {
            Pool::Class(GapClass::Short) => 0,
            Pool::AllLong => 1,
            Pool::Class(GapClass::Long(c)) => 2 + c,
        }
    }

    /// The pools an entry in a gap of `len` frames counts in: its class, and the pooled
    /// long gaps if it is long.
    pub fn of(len: usize) -> impl Iterator<Item = Pool> {
        let class = GapClass::of(len);
        [
            Some(Pool::Class(class)),
            class.is_long().then_some(Pool::AllLong),
        ]
        .into_iter()
        .flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_double_from_the_spline_carry() {
        let carry = SPLINE_CARRY_FRAMES;
        assert_eq!(GapClass::of(1), GapClass::Short);
        assert_eq!(GapClass::of(carry), GapClass::Short);
        assert_eq!(GapClass::of(carry + 1), GapClass::Long(0));
        assert_eq!(GapClass::of(2 * carry), GapClass::Long(0));
        assert_eq!(GapClass::of(2 * carry + 1), GapClass::Long(1));
        assert_eq!(GapClass::of(16 * carry), GapClass::Long(3));
        assert_eq!(GapClass::of(16 * carry + 1), GapClass::Long(4));
        assert_eq!(GapClass::of(1_000_000), GapClass::Long(LENGTH_CLASSES - 1));
        for class in GapClass::all() {
            assert_eq!(GapClass::from_index(class.index()), class);
            // A class's longest gap is in it, one frame more is not.
            if let Some(top) = class.longest() {
                assert_eq!(GapClass::of(top), class);
                assert_ne!(GapClass::of(top + 1), class);
            }
        }
        assert_eq!(GapClass::Long(LENGTH_CLASSES - 1).longest(), None);
    }

    #[test]
    fn a_long_entry_counts_in_its_class_and_the_pool_a_short_one_once() {
        let short: Vec<usize> = Pool::of(3).map(Pool::index).collect();
        assert_eq!(short, [0]);
        let long: Vec<usize> = Pool::of(SPLINE_CARRY_FRAMES * 3).map(Pool::index).collect();
        assert_eq!(long, [3, 1]);
        let mut every: Vec<usize> = GapClass::all()
            .map(|c| Pool::Class(c).index())
            .chain([Pool::AllLong.index()])
            .collect();
        every.sort_unstable();
        assert_eq!(every, (0..Pool::COUNT).collect::<Vec<_>>());
    }
}
