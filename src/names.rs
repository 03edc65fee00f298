//! The names of the library's enums on the command line, in JSON records and in tables.
//!
//! Every such enum derives clap's `ValueEnum` (kebab-case, as its serde spelling), so its
//! name is read from there rather than written again in a hand-made table.

/// The command-line name of `value` (`scaled-se3`, `analytic`, `flex`, …).
pub fn value_name<T: clap::ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .expect("doma's enums skip no variant")
        .get_name()
        .to_string()
}

/// `Display` for enums that derive `ValueEnum`: their command-line name, padded to the
/// formatter's width.
macro_rules! display_as_value_name {
    ($($t:ty),* $(,)?) => {
        $(impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.pad(&$crate::names::value_name(self))
            }
        })*
    };
}
pub(crate) use display_as_value_name;
