//! The batch manifest: a JSON file that lists the sequences of a dataset, each with its
//! overrides of the fit recipe.
//!
//! ```json
//! {
//!   "defaults": { "model": "affinity", "iterations": 1000, "h_weight": 0.1 },
//!   "sequences": [
//!     { "name": "faerie", "data": "md2_faerie.traj", "frames": [112, 132] },
//!     { "data": "cdp_male_wave.traj", "stride": 4, "model": "trans", "seed": 1 },
//!     { "name": "fluid-dpf", "data": "taichi_mpm3d_fluid.traj", "model": "dpf",
//!       "frames": [0, 10], "h_weight": "auto" }
//!   ]
//! }
//! ```
//!
//! Every field of an entry, and of `defaults`, is a [`RunSpec`] field: `data`, `config`,
//! `model` (or `variant`, as the flag: `trans`, `se3`, `scaled-se3`, `affinity`, `dpf`),
//! `backend`, `jacobian`, `iterations` (or `iters`), `h_weight` (a number or `"auto"`), `seed`, `mesh`, `frames` (`[start,
//! end)`), `stride`, `test_fraction`, `checkpoint_every`, `points_per_step`,
//! `frames_per_step`, `frames_per_iteration`, `init_scale`, `time_scale`, and for tracker output `layout`, `frame`, `count_hidden`,
//! `reference_frame`, `drop_unobserved`, `model_outputs`, `holdout_observations`, `blind_validation`,
//! `confidence`,
//! `robust` (`"huber:0.01"`, as `--robust` spells it; the older `data_penalty` object
//! still reads), and `recipe` (`paper`, `fast`) and `until_converged` (a patience in
//! iterations); an entry also
//! has a `name`, its run folder's name (default: the data file's stem). Relative paths are
//! relative to the manifest's folder. Unknown fields are refused.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::run::RunSpec;
use crate::{DomaError, Result};

/// A parsed manifest, its entries resolved (defaults filled in, paths absolute).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// The entries, in the file's order; shard `I/N` runs entries `I, I + N, …`.
    pub items: Vec<BatchItem>,
}

/// One sequence of a batch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BatchItem {
    /// Its run folder's name under the batch folder.
    pub name: String,
    /// What to fit.
    pub spec: RunSpec,
}

/// The file as written: defaults and entries.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    defaults: Option<Value>,
    sequences: Vec<Value>,
}

/// `frames` may be written as the CLI writes it, `"A..B"` (or `"A..=B"`), as well as
/// `[A, B]`: the string becomes the pair.
fn frames_as_pair(fields: &mut serde_json::Map<String, Value>) -> std::result::Result<(), String> {
    if let Some(Value::String(text)) = fields.get("frames") {
        let range = crate::data::parse_frame_range(text).map_err(|e| format!("`frames`: {e}"))?;
        fields.insert("frames".into(), serde_json::json!([range.start, range.end]));
    }
    Ok(())
}

impl Manifest {
    /// Reads and checks the manifest at `path`. Errors name the file and the entry.
    pub fn load(path: &Path) -> Result<Manifest> {
        let text = crate::io::read_input_text(path, crate::io::InputKind::Manifest)?;
        let base = std::path::absolute(path)
            .map_err(|e| DomaError::io(path, e))?
            .parent()
            .map_or_else(|| PathBuf::from("/"), Path::to_path_buf);
        Manifest::parse(&text, &base).map_err(|reason| DomaError::Malformed {
            path: path.to_path_buf(),
            reason,
        })
    }

    /// Parses a manifest's text; relative paths are taken relative to `base`.
    pub fn parse(text: &str, base: &Path) -> std::result::Result<Manifest, String> {
        let file: File = serde_json::from_str(text).map_err(|e| format!("not a manifest: {e}"))?;
        if file.sequences.is_empty() {
            return Err("`sequences` lists no sequence".into());
        }
        let defaults: RunSpec = match file.defaults {
            None => RunSpec::default(),
            Some(Value::Object(mut fields)) => {
                frames_as_pair(&mut fields).map_err(|e| format!("`defaults`: {e}"))?;
                serde_json::from_value(Value::Object(fields))
                    .map_err(|e| format!("`defaults`: {e}"))?
            }
            Some(other) => return Err(format!("`defaults` {other} is not a JSON object")),
        };
        if defaults.data.is_some() {
            return Err("`defaults` cannot name the data; each sequence names its own".into());
        }
        // Names compared without case: `Run` and `run` are one folder on a
        // case-insensitive file system.
        let mut names = BTreeSet::new();
        let mut items = Vec::with_capacity(file.sequences.len());
        for (i, entry) in file.sequences.into_iter().enumerate() {
            let at = |e: String| format!("sequence {i}: {e}");
            let Value::Object(mut fields) = entry else {
                return Err(at("an entry is a JSON object".into()));
            };
            let name = match fields.remove("name") {
                None => None,
                Some(Value::String(s)) => Some(s),
                Some(other) => return Err(at(format!("`name` {other} is not a string"))),
            };
            frames_as_pair(&mut fields).map_err(at)?;
            let spec: RunSpec =
                serde_json::from_value(Value::Object(fields)).map_err(|e| at(e.to_string()))?;
            let spec = spec
                .or(&defaults)
                .map_err(|e| at(e.to_string()))?
                .relative_to(base);
            let data = spec.data.as_deref().ok_or_else(|| at("no `data`".into()))?;
            let name = match name {
                Some(n) => n,
                None => data
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .ok_or_else(|| at("`data` has no file name; give a `name`".into()))?,
            };
            check_name(&name).map_err(at)?;
            if !names.insert(name.to_lowercase()) {
                return Err(at(format!(
                    "the name `{name}` is taken by an earlier sequence (names are compared \
                     without case); give each a distinct `name`"
                )));
            }
            items.push(BatchItem { name, spec });
        }
        Ok(Manifest { items })
    }
}

/// The longest run folder name: far below a file system's 255 bytes.
pub const MAX_NAME: usize = 128;

/// A run folder's name: letters, digits, `.`, `_`, `-`, `+`, `=`; not starting with `.`;
/// at most [`MAX_NAME`] characters; none of the batch folder's own files.
pub fn check_name(name: &str) -> std::result::Result<(), String> {
    if name.len() > MAX_NAME {
        return Err(format!(
            "the name `{}…` has {} characters, more than {MAX_NAME}",
            &name[..name.floor_char_boundary(24)],
            name.chars().count()
        ));
    }
    if super::RESERVED.iter().any(|r| r.eq_ignore_ascii_case(name)) {
        return Err(format!(
            "the name `{name}` is one of the batch folder's own files ({})",
            super::RESERVED.join(", ")
        ));
    }
    let ok = !name.is_empty()
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-+=".contains(c));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "the name `{name}` is not a folder name (use letters, digits, `.`, `_`, `-`, `+`, `=`; no leading `.`)"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::ModelChoice;
    use crate::train::select::Weight;

    #[test]
    fn the_documented_example_parses() {
        let doc = include_str!("manifest.rs");
        let start = doc.find("```json").unwrap() + 7;
        let end = start + doc[start..].find("```").unwrap();
        let text: String = doc[start..end]
            .lines()
            .map(|l| l.trim_start().trim_start_matches("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        let m = Manifest::parse(&text, Path::new("/d")).unwrap();
        let names: Vec<&str> = m.items.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, ["faerie", "cdp_male_wave", "fluid-dpf"]);
        let male = &m.items[1].spec;
        assert_eq!(male.model, Some(ModelChoice::Trans));
        assert_eq!(
            (male.iterations, male.stride, male.seed),
            (Some(1000), Some(4), Some(1))
        );
        assert_eq!(male.h_weight, Some(Weight::Fixed(0.1)));
        assert_eq!(
            male.data.as_deref(),
            Some(Path::new("/d/cdp_male_wave.traj"))
        );
        assert_eq!(m.items[2].spec.h_weight, Some(Weight::Auto));
    }

    #[test]
    fn bad_manifests_say_which_entry_and_why() {
        let cases = [
            (r#"{"sequences": []}"#, "no sequence"),
            (r#"{"sequences": [{"name": "a"}]}"#, "sequence 0: no `data`"),
            (
                r#"{"sequences": [{"data": "a.traj", "iteratons": 3}]}"#,
                "iteratons",
            ),
            (
                r#"{"sequences": [{"data": "x/a.traj"}, {"data": "y/a.traj"}]}"#,
                "sequence 1: the name `a` is taken",
            ),
            (
                r#"{"sequences": [{"data": "a.traj", "name": "../up"}]}"#,
                "not a folder name",
            ),
            (
                r#"{"sequences": [{"data": "a.traj", "model": "bones"}]}"#,
                "bones",
            ),
            (
                r#"{"defaults": {"data": "a"}, "sequences": [{"data": "a.traj"}]}"#,
                "defaults",
            ),
            (r#"{"sequence": []}"#, "sequence"),
            ("[1, 2", "not a manifest"),
        ];
        for (text, needle) in cases {
            let err = Manifest::parse(text, Path::new("/")).unwrap_err();
            assert!(err.contains(needle), "{text}: {err}");
        }
    }

    #[test]
    fn names_that_collide_with_the_batch_or_each_other_or_run_long_are_refused() {
        let long = "n".repeat(300);
        let cases = [
            (
                r#"{"sequences": [{"data": "a.traj", "name": "batch-manifest.json"}]}"#.to_string(),
                "the batch folder's own files",
            ),
            (
                r#"{"sequences": [{"data": "a.traj", "name": "Summary.JSON"}]}"#.into(),
                "the batch folder's own files",
            ),
            (
                r#"{"sequences": [{"data": "a.traj", "name": "Run"}, {"data": "b.traj", "name": "run"}]}"#.into(),
                "sequence 1: the name `run` is taken",
            ),
            (
                format!(r#"{{"sequences": [{{"data": "a.traj", "name": "{long}"}}]}}"#),
                "sequence 0: the name `nnnn",
            ),
        ];
        for (text, needle) in cases {
            let err = Manifest::parse(&text, Path::new("/")).unwrap_err();
            assert!(err.contains(needle), "{text}: {err}");
        }
        let at_bound = "n".repeat(MAX_NAME);
        let text = format!(r#"{{"sequences": [{{"data": "a.traj", "name": "{at_bound}"}}]}}"#);
        assert!(Manifest::parse(&text, Path::new("/")).is_ok());
    }

    #[test]
    fn frames_take_the_clis_spelling_too() {
        let text = r#"{"defaults": {"frames": "0..=9"},
            "sequences": [{"data": "a.traj", "frames": "95..112"}, {"data": "b.traj"},
                          {"data": "c.traj", "frames": [3, 7]}]}"#;
        let m = Manifest::parse(text, Path::new("/")).unwrap();
        let frames: Vec<_> = m.items.iter().map(|i| i.spec.frames).collect();
        assert_eq!(frames, [Some([95, 112]), Some([0, 10]), Some([3, 7])]);
        let err = Manifest::parse(
            r#"{"sequences": [{"data": "a.traj", "frames": "9..3"}]}"#,
            Path::new("/"),
        )
        .unwrap_err();
        assert!(err.contains("sequence 0: `frames`"), "{err}");
    }
}
