//! The names of the library's enums on the command line, in JSON, in Python and in tables.
//!
//! Every such enum derives clap's `ValueEnum` (kebab-case, as its serde spelling), so its
//! name is read from there rather than written again in a hand-made table, and
//! `value_names!` gives it `Display` and `FromStr` from that one spelling: the flag, the
//! JSON field and the Python keyword read the same words, and a wrong one is refused with
//! the list of the right ones.

/// The command-line name of `value` (`scaled-se3`, `analytic`, `flex`, …).
pub fn value_name<T: clap::ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .expect("doma's enums skip no variant")
        .get_name()
        .to_string()
}

/// Every name of `T`, in its declaration order.
pub fn choices<T: clap::ValueEnum>() -> Vec<String> {
    T::value_variants().iter().map(value_name).collect()
}

/// `s` as a value of `T`, spelt exactly as on the command line; the error lists the names.
pub fn parse_value<T: clap::ValueEnum>(s: &str) -> Result<T, String> {
    T::from_str(s, false).map_err(|_| format!("`{s}` is not one of {}", choices::<T>().join(", ")))
}

/// `Display` (the command-line name, padded to the formatter's width) and `FromStr`
/// ([`parse_value`]) for enums that derive `ValueEnum`.
macro_rules! value_names {
    ($($t:ty),* $(,)?) => {
        $(impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.pad(&$crate::names::value_name(self))
            }
        }
        impl std::str::FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                $crate::names::parse_value(s)
            }
        })*
    };
}
pub(crate) use value_names;

#[cfg(test)]
mod tests {
    use crate::backend::BackendKind;
    use crate::data::layout::{CoordFrame, Layout};
    use crate::field::Variant;
    use crate::jacobian::JacobianKind;
    use crate::run::ModelChoice;
    use crate::train::Recipe;

    /// The name a value prints is the one it parses from, and the one serde writes.
    fn round_trip<T>()
    where
        T: clap::ValueEnum + std::fmt::Display + std::str::FromStr<Err = String>,
        T: serde::Serialize + PartialEq + std::fmt::Debug,
    {
        for v in T::value_variants() {
            let name = v.to_string();
            assert_eq!(name.parse::<T>().as_ref(), Ok(v));
            assert_eq!(serde_json::to_value(v).unwrap(), serde_json::json!(name));
        }
        let err = "nonesuch".parse::<T>().unwrap_err();
        let first = super::value_name(&T::value_variants()[0]);
        assert!(err.contains("nonesuch") && err.contains(&first), "{err}");
    }

    #[test]
    fn every_option_enum_prints_parses_and_serialises_one_spelling() {
        round_trip::<Variant>();
        round_trip::<ModelChoice>();
        round_trip::<BackendKind>();
        round_trip::<JacobianKind>();
        round_trip::<Layout>();
        round_trip::<CoordFrame>();
        round_trip::<Recipe>();
        assert_eq!(
            "affine".parse::<ModelChoice>().unwrap_err(),
            "`affine` is not one of trans, se3, scaled-se3, affinity, dpf"
        );
    }
}
