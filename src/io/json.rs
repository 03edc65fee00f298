//! JSON files and JSON values: configs and records written atomically, configs read
//! through the bounded reader, and the overlay of a partial config on a full one (with
//! unknown fields refused rather than ignored).

use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{InputKind, read_input_text, write_atomic};
use crate::{DomaError, Result};

/// Writes `config` as pretty JSON to `path`, atomically.
pub fn save_json<T: Serialize>(config: &T, path: &Path) -> Result<()> {
    let text = serde_json::to_string_pretty(config)
        .map_err(|e| DomaError::InvalidData(format!("cannot serialise {}: {e}", path.display())))?;
    write_atomic(path, text.as_bytes())
}

/// Reads JSON from `path`; a parse error is [`DomaError::Malformed`] naming the file.
pub fn load_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = read_input_text(path, InputKind::Config)?;
    serde_json::from_str(&text).map_err(|e| DomaError::Malformed {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// The JSON object in the config file `path`; errors name the file.
pub fn read_object(path: &Path) -> Result<serde_json::Map<String, Value>> {
    let text = read_input_text(path, InputKind::Config)?;
    let given: Value = serde_json::from_str(&text).map_err(|e| DomaError::Malformed {
        path: path.to_path_buf(),
        reason: format!("not JSON: {e}"),
    })?;
    match given {
        Value::Object(fields) => Ok(fields),
        _ => Err(DomaError::Malformed {
            path: path.to_path_buf(),
            reason: "a config is a JSON object".into(),
        }),
    }
}

/// The first field of `given` (as a dotted path below `at`) that `known`, a full config of
/// the same kind, does not have. Objects are compared key by key; a field whose known
/// value is not an object (a number, or `null` for an unset option) is not looked into.
pub fn unknown_field(given: &Value, known: &Value, at: &str) -> Option<String> {
    let (Value::Object(given), Value::Object(known)) = (given, known) else {
        return None;
    };
    given.iter().find_map(|(key, value)| {
        let path = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        match known.get(key) {
            None => Some(path),
            Some(k) => unknown_field(value, k, &path),
        }
    })
}

/// Overlays `given` on `base`, object by object.
pub fn merge(base: &mut Value, given: Value) {
    match (base, given) {
        (Value::Object(b), Value::Object(g)) => {
            for (k, v) in g {
                match b.get_mut(&k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}
