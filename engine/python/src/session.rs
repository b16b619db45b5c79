//! `jsim.Session`: the engine session (PSF banks, kernels, the integrator, simulators) with numpy in and
//! out, and `jsim.Analysis`, the result of the one analysis pipeline on one image.

use crate::config::PyConfig;
use crate::exposure::{PyExposure, facts_of};
use crate::{OrPy, convert};
use engine::Config;
use engine::analysis::countermeasures::{
    Countermeasure, DEFAULT_CATALOGUE_ERROR_MAS, Plan, TelemetryQuality,
};
use engine::analysis::crowding::Crowding;
use engine::io::analysis_input::{AnalysisInput, ImageParts};
use engine::io::exposure::{TRUTH_HEADER, truth_from_columns};
use engine::io::instrument::CalibrationFlat;
use engine::io::products;
use engine::scoring::image::Scored;
use engine::session::Session;
use engine::simulate::Simulator;
use engine::studies::predict::Predictor;
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeWarning, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use std::sync::Arc;

/// An engine session on one configuration: it builds the PSFs, the ACE series and the scene once and
/// simulates and analyses exposures with them. `backend`: `"auto"` (the GPU when there is one, else the
/// CPU, said once as a warning), `"cpu"` or `"gpu"`.
#[pyclass(name = "Session", module = "jsim")]
pub struct PySession {
    session: Arc<Session>,
    cfg: Config,
}

/// Countermeasure names (a str, comma-separated, or a list of str) as a plan with the engine's default
/// telemetry quality and catalogue error.
pub fn plan_of(names: &Bound<'_, PyAny>) -> PyResult<Plan> {
    let names: Vec<String> = if names.is_instance_of::<PyString>() {
        names
            .extract::<String>()?
            .split(',')
            .map(|s| s.trim().to_string())
            .collect()
    } else {
        names.extract().map_err(|_| {
            PyTypeError::new_err("countermeasures: a str (comma-separated) or a list of str")
        })?
    };
    Plan::parse(
        &names,
        TelemetryQuality::DEFAULT,
        DEFAULT_CATALOGUE_ERROR_MAS,
    )
    .or_py()
}

/// Show the session's notes about the backend (a CPU standing in for a GPU) as Python warnings.
pub fn warn_notes(py: Python<'_>, session: &Session) -> PyResult<()> {
    for note in session.take_notes() {
        PyErr::warn(
            py,
            &py.get_type::<PyRuntimeWarning>(),
            &std::ffi::CString::new(note).unwrap_or_default(),
            1,
        )?;
    }
    Ok(())
}

impl PySession {
    fn simulator(&self, py: Python<'_>) -> PyResult<Arc<Simulator>> {
        let sim = py.detach(|| self.session.simulator(&self.cfg)).or_py()?;
        warn_notes(py, &self.session)?;
        Ok(sim)
    }
}

/// A 2-D real numpy array as float32 ADU (any integer or real dtype; a `TypeError` for others, a
/// `ValueError` for a shape that is not 2-D or empty).
fn image_f32(image: &Bound<'_, PyAny>) -> PyResult<(Vec<f32>, usize, usize)> {
    let np = image.py().import("numpy")?;
    if !image.is_instance(&np.getattr("ndarray")?)? {
        return Err(PyTypeError::new_err(format!(
            "image: a 2-D numpy array or a jsim.Exposure, not {}",
            image.get_type().name()?
        )));
    }
    let kind: String = image.getattr("dtype")?.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "u" | "i" | "f") {
        return Err(PyTypeError::new_err(format!(
            "image: dtype {} is not a real number type (use uint16, int, float32 or float64)",
            image.getattr("dtype")?.str()?
        )));
    }
    let ndim: usize = image.getattr("ndim")?.extract()?;
    if ndim != 2 {
        return Err(PyValueError::new_err(format!(
            "image: must be 2-D (ny, nx), not {ndim}-D"
        )));
    }
    let a = np.call_method1("ascontiguousarray", (image, np.getattr("float32")?))?;
    let a: PyReadonlyArray2<'_, f32> = a.extract()?;
    let (ny, nx) = (a.shape()[0], a.shape()[1]);
    if nx == 0 || ny == 0 {
        return Err(PyValueError::new_err("image: empty"));
    }
    let data = a
        .as_slice()
        .map_err(|_| PyValueError::new_err("image: not contiguous"))?
        .to_vec();
    Ok((data, nx, ny))
}

/// The truth catalogue from a dict of columns (those of `Exposure.truth`).
fn truth_of(d: &Bound<'_, PyDict>) -> PyResult<Vec<engine::simulate::TruthRow>> {
    let np = d.py().import("numpy")?;
    let cols = TRUTH_HEADER
        .iter()
        .map(|name| {
            let c = d.get_item(name)?.ok_or_else(|| {
                PyValueError::new_err(format!(
                    "truth: no column {name:?} (needs {})",
                    TRUTH_HEADER.join(", ")
                ))
            })?;
            let a = np.call_method1("asarray", (c, np.getattr("float64")?))?;
            a.call_method0("ravel")?
                .call_method0("tolist")?
                .extract::<Vec<f64>>()
        })
        .collect::<PyResult<Vec<_>>>()?;
    let n = cols[0].len();
    if cols.iter().any(|c| c.len() != n) {
        return Err(PyValueError::new_err("truth: columns of different lengths"));
    }
    Ok(truth_from_columns(&cols))
}

/// The countermeasures `predict` reports by default (as `jsim predict`).
const DEFAULT_PREDICT: &str = "none,yzones,plate-affine,plate-poly:3,telemetry";

#[pymethods]
impl PySession {
    #[new]
    #[pyo3(signature = (config = None, backend = "auto"))]
    fn new(config: Option<PyConfig>, backend: &str) -> PyResult<Self> {
        let cfg = config.map(|c| c.inner).unwrap_or_default();
        let cfg = cfg.with_override("fidelity.backend", backend).or_py()?;
        cfg.validate().or_py()?;
        Ok(Self {
            session: Arc::new(Session::new()),
            cfg,
        })
    }

    /// The session's configuration (a copy).
    #[getter]
    fn config(&self) -> PyConfig {
        PyConfig {
            inner: self.cfg.clone(),
        }
    }

    /// Simulate exposure `image` (0 ≤ image < `fidelity.images`) of the dataset: the same image as `jsim
    /// simulate` writes to `img_NNN.fits` for the same configuration and seed. Returns a `jsim.Exposure`:
    /// `image` in ADU (uint16 when digitised), `dq` bits, `truth` positions in pixels (0-based, integer =
    /// pixel centre) and fluxes in electrons, `header` cards (GAIN e⁻/ADU, RDNOISE e⁻, EXPTIME s, …), `ace` in
    /// mas against seconds. Releases the GIL; the first call also builds the PSFs, the ACE series and the
    /// scene (seconds), later calls reuse them.
    #[pyo3(signature = (image = 0))]
    fn simulate(&self, py: Python<'_>, image: usize) -> PyResult<PyExposure> {
        let n = self.cfg.fidelity.images;
        if image >= n {
            return Err(PyValueError::new_err(format!(
                "image = {image}: must be 0 … {} (fidelity.images = {n})",
                n.saturating_sub(1)
            )));
        }
        let sim = self.simulator(py)?;
        let exp = py.detach(|| sim.exposure(image)).or_py()?;
        py.check_signals()?;
        PyExposure::new(py, sim, exp)
    }

    /// The polychromatic PSF at the field centre for colour `j_minus_h` (default: the scene's), on its
    /// oversampled grid: `(table, cells_per_px)`. The table holds the fraction of the total flux per cell,
    /// shape `(n, n)` with the optical axis at the central cell.
    #[pyo3(signature = (j_minus_h = None))]
    fn psf<'py>(
        &self,
        py: Python<'py>,
        j_minus_h: Option<f64>,
    ) -> PyResult<(Bound<'py, PyAny>, usize)> {
        let jh = j_minus_h.unwrap_or(self.cfg.scene.j_minus_h);
        if !jh.is_finite() {
            return Err(PyValueError::new_err("j_minus_h: must be finite"));
        }
        let psf = py.detach(|| {
            let bank = self.session.bank(&self.cfg);
            bank.get(jh, &bank.centre_key())
        });
        let n = psf.n();
        Ok((
            convert::plane(py, psf.data.clone(), n, n)?,
            psf.oversampling,
        ))
    }

    /// The whole ACE series of the dataset: `t_s`, `x_mas`, `y_mas` (empty for a static ACE).
    fn ace<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let sim = self.simulator(py)?;
        let d = PyDict::new(py);
        let (t, x, y) = match sim.series() {
            Some(s) => (
                (0..s.x_mas.len()).map(|i| i as f64 * s.dt_s).collect(),
                s.x_mas.clone(),
                s.y_mas.clone(),
            ),
            None => (Vec::new(), Vec::new(), Vec::new()),
        };
        d.set_item("t_s", convert::vector(py, t))?;
        d.set_item("x_mas", convert::vector(py, x))?;
        d.set_item("y_mas", convert::vector(py, y))?;
        Ok(d)
    }

    /// ePSF astrometry of one image: the pipeline `jsim analyze` runs, with the session's analysis settings. `image`
    /// is a `jsim.Exposure` (its header, DQ, truth and configuration come with it: identical to `jsim analyze` on the
    /// file `exposure.write_fits` writes), or a 2-D array in ADU with its `header` (a dict with GAIN, RDNOISE or
    /// RNREAD + SAMPLING, BIASADU, SATURATE, PLTSCALE; missing keys are assumed and listed in `assumptions`),
    /// optionally its `dq` (uint8, same shape), its `truth` (a dict with the columns of `Exposure.truth`: without it
    /// no accuracy is measured) and the `config` it was simulated with (with the header's IMAGEIDX: the exact-epsf
    /// control's simulation, an oracle; the calibration never comes from it). Readout cards in the header (READOUT,
    /// ROWDIR, NCHAN, CHANWID, PIXTIME, TOVERHD, ROTATION) give the timing a telemetry is applied with.
    /// `countermeasure`: one of `jsim.COUNTERMEASURES`. `crowding`: `"auto"` (from the measured source density),
    /// `"on"` (the crowded-field analysis) or `"off"` (isolated stars), as `jsim analyze --crowding`; default: the
    /// session configuration's `analysis.crowding`. `flat`: the calibration flat product (a 2-D array of the image's
    /// shape, e.g. `Exposure.calibration_flat[0]` or `flat_cal.fits`) with its relative error `flat_error`; without
    /// it a bare array is not flat-fielded (said in `assumptions`). The other products, as files, as `jsim
    /// analyze` takes them: `refcat=` (the reference catalogue, `refcat.csv`), `model_psf=` (the design model
    /// PSF, `psf_model.fits`) and `telemetry=` (`telemetry_NNN.fits`, refused when it covers another exposure
    /// than the header's IMAGEIDX): with the flat, the array and its header give `analyze_file`'s result bit
    /// for bit.
    #[pyo3(signature = (image, header = None, *, dq = None, truth = None, config = None, countermeasure = "none", epsf_zones = None, crowding = None, flat = None, flat_error = None, refcat = None, model_psf = None, telemetry = None))]
    #[allow(clippy::too_many_arguments)]
    fn analyze(
        &self,
        py: Python<'_>,
        image: &Bound<'_, PyAny>,
        header: Option<&Bound<'_, PyDict>>,
        dq: Option<&Bound<'_, PyAny>>,
        truth: Option<&Bound<'_, PyDict>>,
        config: Option<PyConfig>,
        countermeasure: &str,
        epsf_zones: Option<usize>,
        crowding: Option<&str>,
        flat: Option<&Bound<'_, PyAny>>,
        flat_error: Option<f64>,
        refcat: Option<std::path::PathBuf>,
        model_psf: Option<std::path::PathBuf>,
        telemetry: Option<std::path::PathBuf>,
    ) -> PyResult<PyAnalysis> {
        let cm: Countermeasure = countermeasure.parse().or_py()?;
        // the session's configuration, with `crowding=` when given
        let mut cfg = self.cfg.clone();
        if let Some(k) = crowding {
            cfg.analysis.crowding = Crowding::parse(k).map_err(PyValueError::new_err)?;
        }
        let input = if let Ok(exp) = image.cast::<PyExposure>() {
            if header.is_some()
                || dq.is_some()
                || truth.is_some()
                || config.is_some()
                || flat.is_some()
                || flat_error.is_some()
                || refcat.is_some()
                || model_psf.is_some()
                || telemetry.is_some()
            {
                return Err(PyTypeError::new_err(
                    "an Exposure brings its own header, dq, truth, config and products (flat, refcat, \
                     model_psf, telemetry): pass none of them",
                ));
            }
            exp.borrow().analysis_input(py, &self.cfg)?
        } else {
            let flat = match (flat, flat_error) {
                (None, None) => None,
                (Some(f), Some(e)) => {
                    if !(0.0..1.0).contains(&e) {
                        return Err(PyValueError::new_err(format!(
                            "flat_error = {e}: allowed [0, 1) (relative 1σ error)"
                        )));
                    }
                    let (data, nx, ny) = image_f32(f)?;
                    Some(CalibrationFlat {
                        nx,
                        ny,
                        data,
                        error: e,
                        source: "flat=".into(),
                    })
                }
                (Some(_), None) => {
                    return Err(PyValueError::new_err(
                        "flat= needs flat_error= (its relative 1σ error, e.g. FLATERR of flat_cal.fits)",
                    ));
                }
                (None, Some(_)) => {
                    return Err(PyValueError::new_err("flat_error= without flat="));
                }
            };
            let index = header.and_then(image_index);
            self.array_input(py, image, header, dq, truth, config, flat)?
                .with_product_files(engine::io::analysis_input::ProductFiles {
                    reference: refcat.as_deref(),
                    model_psf: model_psf.as_deref(),
                    telemetry: telemetry.as_deref(),
                    image_index: index,
                })
                .or_py()?
        };
        let analysis = py
            .detach(|| self.session.analyze_input(&cfg, &input, epsf_zones, cm))
            .or_py()?;
        PyAnalysis::new(py, analysis, &input, &cm)
    }

    /// ePSF astrometry of an image file as `jsim analyze --image path` reads it: the same reader and the same
    /// products — the calibration flat (`flat=`, else `flat_cal.fits` beside the image), the reference
    /// catalogue (`refcat=`, else `refcat.csv`), the attitude telemetry (`telemetry=`, else
    /// `telemetry_NNN.fits`, NNN the image's IMAGEIDX), the design model PSF (`psf_model.fits` beside the
    /// image) and the truth (`truth=`, else the image's TRUTH extension) — so the result is the CLI's, bit
    /// for bit. A focal-plane file (`fp_NNN.fits`) is analysed array by array by `jsim analyze`: here it is
    /// refused by name. A calibrated file of another observatory (HST, JWST: docs/real-images.md) is read
    /// chip by chip: `chip=` its SCI EXTVER, or an image extension's HDU index (needed when it has
    /// several), with `electrons_per_unit=`, `read_noise_e=`, `dq_ignore=` (bits, as `--dq-ignore`),
    /// `bias_units=` and `saturate_units=` (a raw frame's, as `--bias-units` and `--saturate-units`) where
    /// its header is silent or wrong — the
    /// CLI's result for that chip when the chips are not exposures of one pointing compared with each other.
    #[pyo3(signature = (path, *, truth = None, flat = None, refcat = None, telemetry = None, countermeasure = "none", epsf_zones = None, crowding = None, chip = None, electrons_per_unit = None, read_noise_e = None, dq_ignore = None, bias_units = None, saturate_units = None))]
    #[allow(clippy::too_many_arguments)]
    fn analyze_file(
        &self,
        py: Python<'_>,
        path: std::path::PathBuf,
        truth: Option<std::path::PathBuf>,
        flat: Option<std::path::PathBuf>,
        refcat: Option<std::path::PathBuf>,
        telemetry: Option<std::path::PathBuf>,
        countermeasure: &str,
        epsf_zones: Option<usize>,
        crowding: Option<&str>,
        chip: Option<i64>,
        electrons_per_unit: Option<f64>,
        read_noise_e: Option<f64>,
        dq_ignore: Option<&str>,
        bias_units: Option<f64>,
        saturate_units: Option<f64>,
    ) -> PyResult<PyAnalysis> {
        let cm: Countermeasure = countermeasure.parse().or_py()?;
        let mut cfg = self.cfg.clone();
        if let Some(k) = crowding {
            cfg.analysis.crowding = Crowding::parse(k).map_err(PyValueError::new_err)?;
        }
        if !engine::io::analysis_input::focal_plane_arrays(&path)
            .or_py()?
            .is_empty()
        {
            return Err(PyValueError::new_err(format!(
                "{}: a focal-plane file (ARRAY1 …): analyse it with `jsim analyze`, array by array",
                path.display()
            )));
        }
        if !engine::io::calibrated::primary_is_image(&path).or_py()? {
            let sets = engine::io::calibrated::imsets(&path).or_py()?;
            let set = match chip {
                Some(v) => sets.iter().find(|s| s.number() == v),
                None if sets.len() == 1 => sets.first(),
                None => None,
            }
            .ok_or_else(|| {
                let names: Vec<String> = sets.iter().map(|s| s.name()).collect();
                PyValueError::new_err(format!(
                    "{}: chip={chip:?}: the file's chips are [{}] (give chip= one's number: a SCI chip's \
                     EXTVER, an image extension's HDU index)",
                    path.display(),
                    names.join("; ")
                ))
            })?;
            let opts = engine::io::calibrated::ReadOptions {
                electrons_per_unit,
                read_noise_e,
                dq_ignore: dq_ignore
                    .map(engine::io::calibrated::parse_dq_bits)
                    .transpose()
                    .map_err(PyValueError::new_err)?,
                bias_units,
                saturate_units,
            };
            opts.validate().map_err(|e| {
                PyValueError::new_err(format!("{}={}: {}", e.field, e.value, e.rule))
            })?;
            let input = AnalysisInput::read_chip(&path, set, &opts, &cfg).or_py()?;
            let analysis = py
                .detach(|| self.session.analyze_input(&cfg, &input, epsf_zones, cm))
                .or_py()?;
            return PyAnalysis::new(py, analysis, &input, &cm);
        }
        let input = AnalysisInput::read_products(
            &path,
            truth.as_deref(),
            flat.as_deref(),
            refcat.as_deref(),
            telemetry.as_deref(),
            &cfg,
        )
        .or_py()?;
        let analysis = py
            .detach(|| self.session.analyze_input(&cfg, &input, epsf_zones, cm))
            .or_py()?;
        PyAnalysis::new(py, analysis, &input, &cm)
    }

    /// The instant predictor (no image simulated): the expected accuracy [mas] of the dataset per
    /// countermeasure, `{name: mas}`.
    #[pyo3(signature = (countermeasures = None))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        countermeasures: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let plan = match countermeasures {
            Some(c) => plan_of(c)?,
            None => plan_of(&PyString::new(py, DEFAULT_PREDICT).into_any())?,
        };
        let sim = self.simulator(py)?;
        let values = py
            .detach(|| -> engine::Result<Vec<(String, f64)>> {
                let p = Predictor::new(&sim, &self.cfg.analysis)?;
                plan.countermeasures
                    .iter()
                    .map(|c| Ok((c.to_string(), p.predict(c)?)))
                    .collect()
            })
            .or_py()?;
        let d = PyDict::new(py);
        for (k, v) in values {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "jsim.Session(config hash {}, backend {:?})",
            self.cfg.hash_hex(),
            self.cfg.fidelity.backend
        )
    }
}

/// The header's IMAGEIDX, the exposure's index in its dataset: an integer ≥ 0, else `None`.
fn image_index(header: &Bound<'_, PyDict>) -> Option<usize> {
    header
        .get_item("IMAGEIDX")
        .ok()
        .flatten()
        .and_then(|v| v.extract::<f64>().ok())
        .filter(|i| *i >= 0.0 && i.fract() == 0.0)
        .map(|i| i as usize)
}

impl PySession {
    fn array_input(
        &self,
        py: Python<'_>,
        image: &Bound<'_, PyAny>,
        header: Option<&Bound<'_, PyDict>>,
        dq: Option<&Bound<'_, PyAny>>,
        truth: Option<&Bound<'_, PyDict>>,
        config: Option<PyConfig>,
        flat: Option<CalibrationFlat>,
    ) -> PyResult<AnalysisInput> {
        let (data, nx, ny) = image_f32(image)?;
        let empty = PyDict::new(py);
        let header = header.unwrap_or(&empty);
        let number = |k: &str| -> Option<f64> {
            header
                .get_item(k)
                .ok()
                .flatten()
                .and_then(|v| v.extract::<f64>().ok())
        };
        let text = |k: &str| -> Option<String> {
            header
                .get_item(k)
                .ok()
                .flatten()
                .and_then(|v| v.extract::<String>().ok())
        };
        let facts = facts_of(number, text)?;
        let exposure_s = facts.exposure_s;
        let dq: Option<Vec<u8>> = match dq {
            None => None,
            Some(d) => {
                let a: PyReadonlyArray2<'_, u8> = d
                    .extract()
                    .map_err(|_| PyTypeError::new_err("dq: a 2-D uint8 array"))?;
                if a.shape() != [ny, nx] {
                    return Err(PyValueError::new_err(format!(
                        "dq: shape {:?}, the image's is ({ny}, {nx})",
                        a.shape()
                    )));
                }
                Some(a.as_array().iter().copied().collect())
            }
        };
        let truth = truth.map(truth_of).transpose()?;
        let provenance = match config {
            None => None,
            Some(c) => {
                let i = image_index(header).ok_or_else(|| {
                    PyValueError::new_err(
                        "config= needs the header's IMAGEIDX (the exposure index, an integer ≥ 0)",
                    )
                })?;
                c.inner.validate().or_py()?;
                Some((c.inner, i))
            }
        };
        AnalysisInput::from_parts(
            ImageParts {
                nx,
                ny,
                data: &data,
                dq: dq.as_deref(),
                facts,
                plate_scale_header_mas: number("PLTSCALE"),
            },
            truth,
            provenance,
            flat,
            &self.cfg,
        )
        .and_then(|mut input| {
            // the readout timing the header states (READOUT, PIXTIME, …): what a telemetry is applied with
            let card = |k: &str| text(k).or_else(|| number(k).map(|v| v.to_string()));
            let (readout, _) =
                engine::io::readout_header::from_cards(card, ny, exposure_s, &self.cfg)?;
            input.readout = readout;
            Ok(input)
        })
        .map_err(PyValueError::new_err)
    }
}

/// The analysis of one image: `catalogue` (a dict of arrays, the columns of `catalogue.csv`: `x, y` px,
/// `flux_e, sky_e` e⁻, `crlb_x_mas, crlb_y_mas`, `flags`, `truth_id` (−1 unmatched), `dx_mas, dy_mas`
/// fitted − true), `summary` (the report of `summary.json`: `accuracy_mas`, `crlb_median_mas`, …),
/// `assumptions` (what the image did not say), `epsf` (the effective PSF, `epsf_oversampling` nodes per
/// pixel) and the `countermeasure` it was measured under.
#[pyclass(name = "Analysis", module = "jsim", get_all)]
pub struct PyAnalysis {
    catalogue: Py<PyDict>,
    summary: Py<PyAny>,
    assumptions: Py<PyList>,
    epsf: Py<PyAny>,
    epsf_oversampling: usize,
    countermeasure: String,
    plate_scale_mas: f64,
}

impl PyAnalysis {
    fn new(
        py: Python<'_>,
        a: Scored,
        input: &AnalysisInput,
        cm: &engine::analysis::countermeasures::Countermeasure,
    ) -> PyResult<Self> {
        let scale = input.plate_scale_mas;
        let catalogue = convert::table(
            py,
            &products::CATALOGUE_HEADER,
            &products::catalogue_rows(&a.stars, scale),
        )?;
        let n = a.epsf.n();
        Ok(Self {
            catalogue: catalogue.unbind(),
            summary: convert::to_py_json(py, &a.report)?.unbind(),
            assumptions: PyList::new(py, input.assumptions_for(cm))?.unbind(),
            epsf_oversampling: a.epsf.oversampling,
            epsf: convert::plane(py, a.epsf.data, n, n)?.unbind(),
            countermeasure: a.report.countermeasure.clone(),
            plate_scale_mas: scale,
        })
    }
}

#[pymethods]
impl PyAnalysis {
    fn __repr__(&self, py: Python<'_>) -> String {
        let acc = self
            .summary
            .bind(py)
            .get_item("accuracy_mas")
            .and_then(|v| v.extract::<f64>())
            .unwrap_or(f64::NAN);
        format!(
            "jsim.Analysis({}, accuracy {acc:.2} mas)",
            self.countermeasure
        )
    }
}
