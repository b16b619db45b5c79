//! `jsim.Exposure`: one simulated exposure with numpy planes, its truth, its header and its ACE.

use crate::config::PyConfig;
use crate::{OrPy, convert};
use engine::Config;
use engine::config::FlatField;
use engine::io::analysis_input::{AnalysisInput, ImageParts};
use engine::io::exposure as files;
use engine::io::fits::{ImageFacts, Pixels, Value};
use engine::io::instrument::{CalibrationFlat, SurveyModel, reference_catalogue};
use engine::simulate::{Exposure, Simulator};
use numpy::PyReadonlyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::HashMap;
use std::sync::Arc;

/// One simulated exposure. `image` is what the FITS file stores (`uint16` ADU when digitised with ≤ 16
/// bits, else `float32`), shape `(ny, nx)`, indexed `image[y, x]` as astropy does (0-based pixel
/// centres); `dq` the data-quality bits (`uint8`); `truth` the input catalogue (a dict of 1-D arrays,
/// the columns of `truth_NNN.csv`); `header` the primary header cards; `ace` the attitude during the
/// exposure (`t_s`, `x_mas`, `y_mas`).
#[pyclass(name = "Exposure", module = "jsim")]
pub struct PyExposure {
    sim: Arc<Simulator>,
    /// The engine's exposure, its image planes handed to numpy (`image.adu` and `image.dq` are empty,
    /// the noise-free electrons dropped).
    exp: Exposure,
    image: Py<PyAny>,
    dq: Py<PyAny>,
    truth: Py<PyDict>,
    header: Py<PyDict>,
    ace: Py<PyDict>,
}

impl PyExposure {
    pub fn new(py: Python<'_>, sim: Arc<Simulator>, mut exp: Exposure) -> PyResult<Self> {
        let n = exp.image.n;
        let adu = std::mem::take(&mut exp.image.adu);
        let image = match files::stored_u16(&sim.cfg, &adu) {
            Some(u) => convert::plane(py, u, n, n)?,
            None => convert::plane(py, adu, n, n)?,
        };
        let dq = convert::plane(py, std::mem::take(&mut exp.image.dq), n, n)?;
        exp.star_e = Vec::new();
        let (truth_header, truth_rows) = files::truth_table(&sim, &exp.truth);
        let truth = convert::table(py, &truth_header, &truth_rows)?;
        let header = PyDict::new(py);
        // the values as the FITS file's cards hold them (a double keeps 15 significant digits)
        for c in files::headers(&sim, &exp) {
            match c.value {
                Value::F(v) => header.set_item(c.key, engine::io::fits::as_header_f64(v))?,
                Value::I(v) => header.set_item(c.key, v)?,
                Value::U(v) => header.set_item(c.key, v)?,
                Value::S(v) => header.set_item(c.key, v)?,
            }
        }
        let ace = ace_dict(py, &sim, exp.index)?;
        Ok(Self {
            sim,
            exp,
            image: image.unbind(),
            dq: dq.unbind(),
            truth: truth.unbind(),
            header: header.unbind(),
            ace: ace.unbind(),
        })
    }

    /// The image planes as the FITS writer and the analysis take them (the arrays as they are now).
    fn with_planes<R>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(Pixels<'_>, &[u8]) -> PyResult<R>,
    ) -> PyResult<R> {
        let n = self.exp.image.n;
        let image = self.image.bind(py);
        let dq: PyReadonlyArray2<'_, u8> = self.dq.bind(py).extract()?;
        let dq = dq
            .as_slice()
            .map_err(|_| PyValueError::new_err("dq: not a contiguous uint8 array"))?;
        if image.getattr("shape")?.extract::<(usize, usize)>()? != (n, n) || dq.len() != n * n {
            return Err(PyValueError::new_err(format!(
                "image and dq must stay {n}×{n}"
            )));
        }
        if let Ok(a) = image.extract::<PyReadonlyArray2<'_, u16>>() {
            let s = a
                .as_slice()
                .map_err(|_| PyValueError::new_err("image: not contiguous"))?;
            f(Pixels::U16(s), dq)
        } else {
            let a: PyReadonlyArray2<'_, f32> = image.extract()?;
            let s = a
                .as_slice()
                .map_err(|_| PyValueError::new_err("image: not contiguous"))?;
            f(Pixels::F32(s), dq)
        }
    }

    /// What `jsim analyze` reads from this exposure's FITS file: the image in ADU, its header facts, its
    /// DQ and TRUTH, and its own configuration and index (the simulation context).
    pub fn analysis_input(&self, py: Python<'_>, fallback: &Config) -> PyResult<AnalysisInput> {
        let header: HashMap<String, Value> = files::headers(&self.sim, &self.exp)
            .into_iter()
            .map(|c| (c.key, c.value))
            .collect();
        let facts = facts_of(
            |k| match header.get(k) {
                Some(Value::F(v)) => Some(engine::io::fits::as_header_f64(*v)),
                Some(Value::I(v)) => Some(*v as f64),
                Some(Value::U(v)) => Some(*v as f64),
                _ => None,
            },
            |k| match header.get(k) {
                Some(Value::S(s)) => Some(s.clone()),
                _ => None,
            },
        )?;
        let n = self.exp.image.n;
        self.with_planes(py, |pixels, dq| {
            let data: Vec<f32> = match pixels {
                Pixels::U16(s) => s.iter().map(|v| *v as f32).collect(),
                Pixels::F32(s) => s.to_vec(),
                Pixels::F64(s) => s.iter().map(|v| *v as f32).collect(),
            };
            AnalysisInput::from_parts(
                ImageParts {
                    nx: n,
                    ny: n,
                    data: &data,
                    dq: Some(dq),
                    facts,
                    // as the file's PLTSCALE card holds it
                    plate_scale_header_mas: Some(engine::io::fits::as_header_f64(
                        self.sim.cfg.instrument.plate_scale_mas(),
                    )),
                },
                Some(self.exp.truth.clone()),
                Some((self.sim.cfg.clone(), self.exp.index)),
                self.calibration_flat_product(),
                fallback,
            )
            .map(|mut input| {
                // the reference catalogue product, as `write_fits` writes it beside the image
                input.reference = Some(
                    reference_catalogue(&self.sim, &SurveyModel::default(), 0)
                        .iter()
                        .map(engine::io::instrument::RefStar::catalogue_star)
                        .collect(),
                );
                // the design model PSF, as `write_fits` writes it (f32 in the file, as read back there)
                input.model_psf = engine::io::instrument::model_psf_product(&self.sim).ok();
                // the attitude telemetry (the default quality) and the readout timing, as `write_fits`
                // writes them beside and in the image
                let source = engine::session::Source::new(&self.sim, self.exp.index);
                input.readout = Some(source.readout());
                input.telemetry = source
                    .telemetry_record(&engine::analysis::countermeasures::TelemetryQuality::DEFAULT)
                    .ok()
                    .flatten();
                // the truth in the header's frame, as the TRUTH extension's x_header, y_header (a
                // catalogue-referenced countermeasure is scored against it, as `jsim analyze` scores it)
                input.truth_in_header =
                    engine::scoring::image::catalogue_truth(&self.sim, &self.exp.truth);
                input
            })
            .map_err(PyValueError::new_err)
        })
    }
}

impl PyExposure {
    /// The calibration flat product of this exposure's detector (what `write_fits` writes beside the
    /// image as `flat_cal.fits`), when the analysis is calibrated.
    fn calibration_flat_product(&self) -> Option<CalibrationFlat> {
        let FlatField::Calibrated { error } = self.sim.cfg.analysis.flat_field else {
            return None;
        };
        let n = self.exp.image.n;
        self.sim.calibration_flat().map(|f| CalibrationFlat {
            nx: n,
            ny: n,
            data: f.to_vec(),
            error,
            source: "the exposure's calibration flat".into(),
        })
    }
}

/// The header facts, a bad value a `ValueError` naming its key.
pub fn facts_of(
    number: impl FnMut(&str) -> Option<f64>,
    text: impl FnMut(&str) -> Option<String>,
) -> PyResult<ImageFacts> {
    ImageFacts::from_keys(number, text).map_err(PyValueError::new_err)
}

/// The ACE series over exposure `index` (its whole span, overheads included), as a dict of arrays; empty
/// arrays for a static ACE.
fn ace_dict<'py>(py: Python<'py>, sim: &Simulator, index: usize) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let (mut t, mut x, mut y) = (Vec::new(), Vec::new(), Vec::new());
    if let Some(s) = sim.series() {
        let t0 = sim.exposure_start_s(index);
        let t1 = t0 + sim.timing.span_s();
        let i0 = ((t0 / s.dt_s).floor().max(0.0) as usize).min(s.x_mas.len());
        let i1 = ((t1 / s.dt_s).ceil().max(0.0) as usize + 1).min(s.x_mas.len());
        for i in i0..i1 {
            t.push(i as f64 * s.dt_s);
            x.push(s.x_mas[i]);
            y.push(s.y_mas[i]);
        }
    }
    d.set_item("t_s", convert::vector(py, t))?;
    d.set_item("x_mas", convert::vector(py, x))?;
    d.set_item("y_mas", convert::vector(py, y))?;
    Ok(d)
}

#[pymethods]
impl PyExposure {
    /// The image as stored in the FITS file: `uint16` ADU (digitised, ≤ 16 bits) or `float32` ADU, shape
    /// `(ny, nx)`, `image[y, x]`; handed over from the engine without a copy.
    #[getter]
    fn image(&self, py: Python<'_>) -> Py<PyAny> {
        self.image.clone_ref(py)
    }

    /// Data-quality bits, `uint8`, shape `(ny, nx)`: 1 outside the photosensitive area, 2 full well
    /// reached, 4 ADC high, 8 ADC low.
    #[getter]
    fn dq(&self, py: Python<'_>) -> Py<PyAny> {
        self.dq.clone_ref(py)
    }

    /// The input catalogue: `id, x, y` (px, 0-based, integer = pixel centre), `mag_hw, j_h, flux_e` (e⁻
    /// delivered during the star's window), `psf_fraction, t_start_s, exptime_s, jitter_dx, jitter_dy`
    /// (px: the mean ACE displacement over the window), `ra_deg, dec_deg` (through the image's WCS) — a
    /// dict of 1-D arrays.
    #[getter]
    fn truth(&self, py: Python<'_>) -> Py<PyDict> {
        self.truth.clone_ref(py)
    }

    /// The primary header cards of the FITS file, `{KEY: value}` (GAIN in e⁻/ADU, RDNOISE in e⁻, SEED, …).
    #[getter]
    fn header(&self, py: Python<'_>) -> Py<PyDict> {
        self.header.clone_ref(py)
    }

    /// The attitude control error during this exposure: `t_s` (s from the series start), `x_mas`, `y_mas`.
    #[getter]
    fn ace(&self, py: Python<'_>) -> Py<PyDict> {
        self.ace.clone_ref(py)
    }

    /// The exposure's index in its dataset (its noise streams and its place in the ACE series).
    #[getter]
    fn index(&self) -> usize {
        self.exp.index
    }

    /// The configuration the exposure was simulated with (the FITS file's CONFIG extension).
    #[getter]
    fn config(&self) -> PyConfig {
        PyConfig {
            inner: self.sim.cfg.clone(),
        }
    }

    /// Write the FITS file `jsim simulate` writes for this exposure (image, DQ, TRUTH, CONFIG), atomically,
    /// with the `image` and `dq` arrays as they are now, and beside it the instrument products that
    /// `jsim analyze` reads: the calibration flat (`flat_cal.fits`, when the analysis is calibrated) and the
    /// reference catalogue (`refcat.csv`, the default survey model).
    fn write_fits(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        self.with_planes(py, |pixels, dq| {
            files::write_image_file(&path, &self.sim, &self.exp, pixels, dq).or_py()
        })?;
        let dir = path.parent().unwrap_or(std::path::Path::new("."));
        engine::io::instrument::write_calibration_flat(dir, &*self.sim).or_py()?;
        engine::io::instrument::write_reference_catalogue(dir, &*self.sim, &SurveyModel::default())
            .or_py()?;
        engine::io::instrument::write_model_psf(dir, &*self.sim).or_py()?;
        engine::io::instrument::write_telemetry(
            dir,
            &self.sim,
            self.exp.index,
            &engine::analysis::countermeasures::TelemetryQuality::DEFAULT,
        )
        .or_py()?;
        Ok(())
    }

    /// The calibration flat product `(flat, relative_error)` of the exposure's detector (the true flat
    /// with its calibration error), or `None` when the analysis is uncalibrated: pass it to
    /// `Session.analyze(..., flat=, flat_error=)` with a bare array.
    #[getter]
    fn calibration_flat<'py>(&self, py: Python<'py>) -> PyResult<Option<(Bound<'py, PyAny>, f64)>> {
        match self.calibration_flat_product() {
            None => Ok(None),
            Some(f) => Ok(Some((
                crate::convert::plane(py, f.data.iter().map(|v| *v as f64).collect(), f.nx, f.ny)?,
                f.error,
            ))),
        }
    }

    fn __repr__(&self) -> String {
        let n = self.exp.image.n;
        format!(
            "jsim.Exposure(index={}, {n}×{n} px, {} stars, backend={})",
            self.exp.index,
            self.exp.truth.len(),
            self.exp.backend
        )
    }
}
