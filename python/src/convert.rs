//! Python values into the library's types, each crossing in one place.
//!
//! - A library enum named by a string (`backend="flex"`, `layout="masked"`) is a
//!   [`Wrap<T>`], parsed by the enum's own `FromStr`: the spelling of the command line and
//!   of JSON, and an error that lists the choices.
//! - The options of a fit are the keywords of `doma.fit`, deserialised into the library's
//!   one options type ([`RunSpec`]) by serde, field by field so that an error names its
//!   keyword. A new fit option therefore needs no code here.

use std::str::FromStr;

use doma::backend::BackendKind;
use doma::data::layout::{CoordFrame, Layout};
use doma::run::RunSpec;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde_json::{Map, Number, Value};

/// A library enum read from a Python string.
pub struct Wrap<T>(pub T);

/// An enum that a Python argument names, and the argument's name for its errors.
pub trait Choice: FromStr<Err = String> {
    /// The argument, as the error names it.
    const ARGUMENT: &'static str;
}

impl Choice for BackendKind {
    const ARGUMENT: &'static str = "backend";
}

impl Choice for Layout {
    const ARGUMENT: &'static str = "layout";
}

impl Choice for CoordFrame {
    const ARGUMENT: &'static str = "frame";
}

impl<'a, 'py, T: Choice> FromPyObject<'a, 'py> for Wrap<T> {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let name: String = obj.extract().map_err(|_| {
            PyTypeError::new_err(format!(
                "{} must be a string, not {}",
                T::ARGUMENT,
                type_name(&obj)
            ))
        })?;
        name.parse()
            .map(Wrap)
            .map_err(|e| PyValueError::new_err(format!("{} {e}", T::ARGUMENT)))
    }
}

/// The fit options given as keywords (`None` values left out: the library's default).
/// An unknown keyword is a `TypeError`, as for any Python function; a value of the wrong
/// type a `TypeError`, a wrong value a `ValueError`; each names its keyword.
pub fn run_spec(options: Option<&Bound<'_, PyDict>>) -> PyResult<RunSpec> {
    let mut fields = Map::new();
    for (key, value) in options.into_iter().flat_map(|d| d.iter()) {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        let value = to_json(&value).map_err(|e| e.named(&key))?;
        // Alone first, so that a refusal names its keyword.
        let one = Value::Object(Map::from_iter([(key.clone(), value.clone())]));
        if let Err(e) = serde_json::from_value::<RunSpec>(one) {
            let text = e.to_string();
            return Err(if text.starts_with("unknown field") {
                PyTypeError::new_err(format!("fit() got an unexpected keyword argument '{key}'"))
            } else if text.starts_with("invalid type") {
                PyTypeError::new_err(format!("{key}: {text}"))
            } else {
                PyValueError::new_err(format!("{key}: {text}"))
            });
        }
        fields.insert(key, value);
    }
    let spec: RunSpec = serde_json::from_value(Value::Object(fields))
        .map_err(|e| PyValueError::new_err(format!("fit options: {e}")))?;
    spec.validate().map_err(crate::errors::to_py)?;
    Ok(spec)
}

/// Why a Python value has no JSON form.
enum Unfit {
    Type(String),
    Value(String),
}

impl Unfit {
    fn named(self, key: &str) -> PyErr {
        match self {
            Unfit::Type(m) => PyTypeError::new_err(format!("{key}: {m}")),
            Unfit::Value(m) => PyValueError::new_err(format!("{key}: {m}")),
        }
    }
}

/// A keyword's value as JSON: `bool`, integers (and anything with `__index__`, as NumPy's
/// integers), finite floats (and anything with `__float__`), strings, paths
/// (`os.PathLike`), and lists or tuples of these.
fn to_json(value: &Bound<'_, PyAny>) -> Result<Value, Unfit> {
    let repr = || {
        value
            .repr()
            .map_or_else(|_| "the value".into(), |r| r.to_string())
    };
    if value.is_none() {
        return Ok(Value::Null);
    }
    if let Ok(b) = value.cast::<PyBool>() {
        return Ok(Value::Bool(b.is_true()));
    }
    if value.is_instance_of::<PyString>() {
        let s = value
            .extract::<String>()
            .map_err(|e| Unfit::Value(e.to_string()))?;
        return Ok(Value::String(s));
    }
    if value.is_instance_of::<PyInt>() || value.hasattr("__index__").unwrap_or(false) {
        if let Ok(i) = value.extract::<i64>() {
            return Ok(Value::Number(i.into()));
        }
        if let Ok(u) = value.extract::<u64>() {
            return Ok(Value::Number(u.into()));
        }
        return Err(Unfit::Value(format!("{} is out of range", repr())));
    }
    if value.is_instance_of::<PyFloat>() || value.hasattr("__float__").unwrap_or(false) {
        let f: f64 = value
            .extract()
            .map_err(|_| Unfit::Type(format!("{} is not a number", repr())))?;
        return Number::from_f64(f)
            .map(Value::Number)
            .ok_or_else(|| Unfit::Value(format!("{} is not a finite number", repr())));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()
            .map_err(|e| Unfit::Type(e.to_string()))?
            .map(|item| {
                item.map_err(|e| Unfit::Type(e.to_string()))
                    .and_then(|i| to_json(&i))
            })
            .collect::<Result<Vec<Value>, Unfit>>()?;
        return Ok(Value::Array(items));
    }
    if value.hasattr("__fspath__").unwrap_or(false) {
        let path = value
            .call_method0("__fspath__")
            .and_then(|p| p.extract::<String>())
            .map_err(|e| Unfit::Type(e.to_string()))?;
        return Ok(Value::String(path));
    }
    Err(Unfit::Type(format!(
        "a value of type {} is not an option value",
        type_name(value)
    )))
}

/// The Python type's name of `value`.
fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// Every choice of the library's enums that a Python argument takes, by argument: what
/// `doma.VARIANTS`, `doma.BACKENDS`, … are made of.
pub fn choices(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    use doma::names::choices;
    let table = PyDict::new(py);
    table.set_item("variant", choices::<doma::run::ModelChoice>())?;
    table.set_item("backend", choices::<BackendKind>())?;
    table.set_item("jacobian", choices::<doma::jacobian::JacobianKind>())?;
    table.set_item("recipe", choices::<doma::train::Recipe>())?;
    table.set_item("step", choices::<doma::train::StepKind>())?;
    table.set_item("optimizer", choices::<doma::train::OptimizerKind>())?;
    table.set_item("layout", choices::<Layout>())?;
    table.set_item("frame", choices::<CoordFrame>())?;
    table.set_item("filler", crate::fill::names())?;
    Ok(table)
}
