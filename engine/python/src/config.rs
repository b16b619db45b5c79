//! `jsim.Config`: the engine's configuration, read from TOML, changed field by field, validated once.

use crate::{OrPy, convert};
use engine::Config;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyFloat, PyInt, PyList, PyString, PyTuple};

/// The simulator's configuration (the same TOML as `jsim --config`; `jsim config --print-default` lists
/// every field with its unit and range).
#[pyclass(name = "Config", module = "jsim", from_py_object)]
#[derive(Clone)]
pub struct PyConfig {
    pub inner: Config,
}

/// A Python value as the TOML text `--set FIELD=VALUE` would take.
pub(crate) fn toml_text(v: &Bound<'_, PyAny>) -> PyResult<String> {
    if v.is_instance_of::<PyBool>() {
        return Ok(if v.extract::<bool>()? {
            "true"
        } else {
            "false"
        }
        .into());
    }
    if v.is_instance_of::<PyInt>() {
        return Ok(v.extract::<i64>()?.to_string());
    }
    if v.is_instance_of::<PyFloat>() {
        let x: f64 = v.extract()?;
        return Ok(if x.is_nan() {
            "nan".into()
        } else if x.is_infinite() {
            if x > 0.0 { "inf" } else { "-inf" }.into()
        } else {
            format!("{x:?}")
        });
    }
    if v.is_instance_of::<PyString>() {
        return v.extract::<String>();
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let items: Vec<String> = v
            .try_iter()?
            .map(|x| {
                let x = x?;
                if x.is_instance_of::<PyString>() {
                    Ok(serde_json::to_string(&x.extract::<String>()?)
                        .unwrap_or_else(|_| "\"\"".into()))
                } else {
                    toml_text(&x)
                }
            })
            .collect::<PyResult<_>>()?;
        return Ok(format!("[{}]", items.join(", ")));
    }
    Err(PyTypeError::new_err(format!(
        "a config value must be a bool, int, float, str or a list of them, not {}",
        v.get_type().name()?
    )))
}

#[pymethods]
impl PyConfig {
    /// The default configuration: the paper's scene (400 stars, Hw 12.5, J − H = 2), realistic ACE,
    /// rolling readout, 11 images, imaged by a typical instrument as built (`[as_built]`; products from the
    /// design).
    #[staticmethod]
    fn default() -> Self {
        Self {
            inner: Config::default(),
        }
    }

    /// A copy imaged by the telescope exactly as designed: every `[as_built]` deviation 0, its seed and
    /// knowledge kept (what `--instrument design` does on the command line: the control).
    fn as_designed(&self) -> Self {
        let mut inner = self.inner.clone();
        inner.as_built = inner
            .as_built
            .for_instrument(engine::config::InstrumentModel::Design);
        Self { inner }
    }

    /// A configuration from a TOML file (a `pathlib.Path`, or a `str` without `=`: a file name) or from
    /// TOML text (a `str` with `key = value` lines); fields left out keep their defaults. Raises
    /// `ValueError` naming a bad field, `OSError` for a file that cannot be read.
    #[staticmethod]
    fn from_toml(path_or_str: &Bound<'_, PyAny>) -> PyResult<Self> {
        let path: Option<std::path::PathBuf> = if path_or_str.is_instance_of::<PyString>() {
            // TOML text always holds a `key = value` (or is empty: the defaults); anything else names a file
            let s: String = path_or_str.extract()?;
            (!s.trim().is_empty() && !s.contains('\n') && !s.contains('='))
                .then(|| std::path::PathBuf::from(&s))
        } else {
            Some(path_or_str.extract().map_err(|_| {
                PyTypeError::new_err("from_toml takes a path or a str of TOML text")
            })?)
        };
        let inner = match path {
            Some(p) => Config::load(&p).or_py()?,
            None => Config::from_toml_str(&path_or_str.extract::<String>()?).or_py()?,
        };
        Ok(Self { inner })
    }

    /// Set one field by its dotted path (`"ace.sigma_mas"`, `"readout.order"`, `"ace.modes.0.freq_hz"`),
    /// as `--set FIELD=VALUE` does. Ranges are checked once, by `validate()` or when a `Session` is made,
    /// so the order of the changes never matters. Raises `ValueError` naming an unknown field or a value
    /// of the wrong kind.
    fn set(&mut self, field: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let text = toml_text(value)?;
        self.inner = self.inner.with_override(field, &text).or_py()?;
        Ok(())
    }

    /// The value of one field by its dotted path (numbers, strings, lists and dicts).
    fn get<'py>(&self, py: Python<'py>, field: &str) -> PyResult<Bound<'py, PyAny>> {
        let mut v =
            serde_json::to_value(&self.inner).map_err(|e| PyValueError::new_err(e.to_string()))?;
        for key in field.split('.') {
            v = match v {
                serde_json::Value::Object(mut m) => m.remove(key),
                serde_json::Value::Array(mut a) => key
                    .parse::<usize>()
                    .ok()
                    .filter(|i| *i < a.len())
                    .map(|i| a.swap_remove(i)),
                _ => None,
            }
            .ok_or_else(|| PyValueError::new_err(format!("{field}: no such config field")))?;
        }
        convert::json_to_py(py, &v)
    }

    /// Check every field's range; raises `ValueError` naming the first bad field and its allowed range.
    fn validate(&self) -> PyResult<()> {
        self.inner.validate().or_py()
    }

    /// The configuration as TOML (what `--config` reads).
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    /// The configuration's hash (the `CONFHASH` header: SHA-256 of the TOML, 16 hex digits).
    fn hash(&self) -> String {
        self.inner.hash_hex()
    }

    /// A copy.
    fn copy(&self) -> Self {
        self.clone()
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "jsim.Config(hash={}, seed={}, ace={}, readout={}, mag_hw={}, images={})",
            c.hash_hex(),
            c.seed,
            c.ace.case.name(),
            c.readout.order.name(),
            c.scene.mag_hw,
            c.fidelity.images
        )
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.inner == other.inner
    }
}
