"""Type stubs of the jsim module (the Rust extension jsim._jsim and its Python wrapper)."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
COUNTERMEASURES: str
"""The countermeasure names: none, yzones[:K], yzones-shared[:K], plate-affine[@R], plate-poly:N[@R]
(R: stack (default), catalogue, oracle), telemetry, exact-epsf."""

Table = Dict[str, Union[npt.NDArray[np.float64], npt.NDArray[np.int64], List[str]]]
ConfigValue = Union[bool, int, float, str, Sequence[Union[bool, int, float, str]]]

class Config:
    """The simulator's configuration (the TOML of ``jsim --config``)."""

    @staticmethod
    def default() -> Config:
        """The default configuration: the paper's scene (400 stars, Hw 12.5, J − H = 2), realistic
        ACE, rolling readout, 11 images."""
    @staticmethod
    def from_toml(path_or_str: Union[str, PathLike[str]]) -> Config:
        """From a TOML file (a path, or a str naming an existing file) or TOML text; ValueError names a
        bad field."""
    def set(self, field: str, value: ConfigValue) -> None:
        """Set one field by dotted path (``"ace.sigma_mas"``, ``"ace.modes.0.freq_hz"``); ValueError
        names an unknown field or a value of the wrong kind. Ranges are checked by ``validate()`` or
        when a Session is made."""
    def get(self, field: str) -> Any:
        """The value of one field by dotted path."""
    def validate(self) -> None:
        """Check every range; ValueError names the first bad field and its allowed range."""
    def to_toml(self) -> str:
        """The configuration as TOML."""
    def hash(self) -> str:
        """The CONFHASH header: SHA-256 of the TOML, 16 hex digits."""
    def copy(self) -> Config: ...

class Exposure:
    """One simulated exposure."""

    @property
    def image(self) -> Union[npt.NDArray[np.uint16], npt.NDArray[np.float32]]:
        """ADU as the FITS file stores it (uint16 when digitised with ≤ 16 bits, else float32), shape
        (ny, nx), ``image[y, x]``; handed over without a copy."""
    @property
    def dq(self) -> npt.NDArray[np.uint8]:
        """Data-quality bits, shape (ny, nx): 1 border, 2 full well, 4 ADC high, 8 ADC low."""
    @property
    def truth(self) -> Table:
        """The input catalogue: id, x, y [px], mag_hw, j_h, flux_e [e-], psf_fraction, t_start_s,
        exptime_s, jitter_dx, jitter_dy [px], ra_deg, dec_deg (through the image's WCS)."""
    @property
    def header(self) -> Dict[str, Union[float, int, str]]:
        """The primary header cards (GAIN e-/ADU, RDNOISE e-, SEED, …)."""
    @property
    def ace(self) -> Dict[str, npt.NDArray[np.float64]]:
        """The attitude during the exposure: t_s, x_mas, y_mas."""
    @property
    def index(self) -> int: ...
    @property
    def config(self) -> Config: ...
    @property
    def calibration_flat(self) -> Optional[Tuple[npt.NDArray[np.float64], float]]:
        """The calibration flat product (flat, relative error), or None when uncalibrated."""
    def write_fits(self, path: Union[str, PathLike[str]]) -> None:
        """Write the FITS file ``jsim simulate`` writes (image, DQ, TRUTH, CONFIG)."""

class Analysis:
    """ePSF astrometry of one image."""

    catalogue: Table
    """x, y [px], flux_e, sky_e [e-], crlb_x_mas, crlb_y_mas, flags, truth_id (-1 unmatched), dx_mas,
    dy_mas (fitted − true)."""
    summary: Dict[str, Any]
    """The report of summary.json: accuracy_mas (std of fitted − true, combined), accuracy_x_mas,
    accuracy_y_mas, crlb_median_mas, accuracy_over_crlb, n_detected, n_used, …"""
    assumptions: List[str]
    epsf: npt.NDArray[np.float64]
    epsf_oversampling: int
    countermeasure: str
    plate_scale_mas: float

class Session:
    """An engine session on one configuration."""

    def __init__(self, config: Optional[Config] = None, backend: str = "auto") -> None:
        """``backend``: "auto" (GPU if present, else CPU with a RuntimeWarning), "cpu" or "gpu".
        ValueError names a bad configuration field."""
    @property
    def config(self) -> Config: ...
    def simulate(self, image: int = 0) -> Exposure:
        """Simulate exposure ``image`` (0 ≤ image < fidelity.images): the image ``jsim simulate``
        writes for the same configuration and seed. Releases the GIL."""
    def psf(self, j_minus_h: Optional[float] = None) -> Tuple[npt.NDArray[np.float64], int]:
        """The polychromatic PSF at the field centre: (table of flux fraction per cell, cells per px)."""
    def ace(self) -> Dict[str, npt.NDArray[np.float64]]:
        """The dataset's ACE series: t_s [s], x_mas, y_mas [mas]."""
    def analyze(
        self,
        image: Union[Exposure, npt.ArrayLike],
        header: Optional[Dict[str, Union[float, int, str]]] = None,
        *,
        dq: Optional[npt.NDArray[np.uint8]] = None,
        truth: Optional[Table] = None,
        config: Optional[Config] = None,
        countermeasure: str = "none",
        epsf_zones: Optional[int] = None,
        crowding: Optional[str] = None,
        flat: Optional[npt.ArrayLike] = None,
        flat_error: Optional[float] = None,
    ) -> Analysis:
        """ePSF astrometry of one image (``jsim analyze``): an Exposure, or a 2-D ADU array with its
        header (GAIN, RDNOISE or RNREAD+SAMPLING, BIASADU, SATURATE, PLTSCALE, IMAGEIDX), dq, truth,
        the config it was simulated with and the calibration flat product (``flat``, ``flat_error``).
        ``crowding``: auto, on or off (default: the session configuration's ``analysis.crowding``).
        TypeError for a non-numeric dtype, ValueError for a shape that is not 2-D."""
    def analyze_file(
        self,
        path: Union[str, PathLike[str]],
        *,
        truth: Union[str, PathLike[str], None] = None,
        flat: Union[str, PathLike[str], None] = None,
        refcat: Union[str, PathLike[str], None] = None,
        telemetry: Union[str, PathLike[str], None] = None,
        countermeasure: str = "none",
        epsf_zones: Optional[int] = None,
        crowding: Optional[str] = None,
    ) -> Analysis:
        """``jsim analyze --image path`` from Python: the same reader and products (flat_cal.fits,
        refcat.csv, telemetry_NNN.fits, psf_model.fits beside the image, or the paths given), the CLI's
        result bit for bit. A focal-plane file is refused (ValueError)."""
    def predict(self, countermeasures: Union[str, Sequence[str], None] = None) -> Dict[str, float]:
        """The instant predictor: expected accuracy [mas] per countermeasure."""

def score(
    measured: Dict[str, npt.ArrayLike],
    truth: Dict[str, npt.ArrayLike],
    *,
    plate_scale_mas: float,
    match_radius_px: float = 1.0,
    offset_search_px: float = 20.0,
    bin_mag: float = 1.0,
) -> Dict[str, Any]:
    """The scoring step (``jsim score``): completeness, accuracy and false detections per magnitude bin
    of measured x, y (optional flags, array) against a truth x, y, mag (optional array)."""

def solve(
    observations: Dict[str, npt.ArrayLike],
    exposures: Dict[str, npt.ArrayLike],
    references: Dict[str, npt.ArrayLike],
    *,
    model: str = "full",
    method: str = "cg",
    tolerance_sigma: float = 1e-3,
    clip_sigma: float = 5.0,
    max_iterations: int = 500,
    excess_noise: str = "none",
) -> Dict[str, Any]:
    """The astrometric solution (what ``jsim solve`` runs on a sequence's observations) on one tangent
    plane, mas: ``observations`` (``exposure, source, xi_mas, eta_mas, sigma_mas``), ``exposures``
    (``t_yr, parallax_xi, parallax_eta, centre_xi_mas, centre_eta_mas``, optionally ``stare`` and ``visit``:
    the groups whose observations of a source share an error for ``excess_noise`` = ``"per-stare"`` or
    ``"per-visit"``, each exposure its own by default), ``references`` (``source``,
    ``xi_mas, eta_mas, pm_xi, pm_eta, parallax`` and their ``sigma_…``). Returns per-source arrays (the five
    parameters, their ``sigma_…``, ``observations``, ``chi2``), per-exposure attitudes (``p, q,
    offset_xi_mas, offset_eta_mas``; NaN for an exposure left out, listed in ``skipped_exposures``) and
    ``iterations, converged, rejected, chi2_per_dof`` (and the excess noise measured, ``excess_tau_mas`` per
    bin of per-observation σ ``excess_sigma_obs_mas``)."""

def solve_sequence(
    sequence: str,
    *,
    exposures: Optional[List[int]] = None,
    out: Optional[str] = None,
    model: str = "auto",
    method: str = "cg",
    every: int = 1,
    excess_noise: str = "none",
) -> Dict[str, Any]:
    """``jsim solve`` on a sequence that has run (``jsim sequence --out``): the solution of its first N
    exposures for each N in ``exposures`` (default: all that have run; of every ``every``-th exposure of each
    stare, ``--every``), from its products, scored against its truth, the sources' σ carrying the
    ``excess_noise`` (``none``, ``per-stare`` or ``per-visit``: ``--excess-noise``); writes ``jsim solve``'s files to ``out`` (default ``solution/`` in the sequence's directory)
    and returns ``summary`` (``solution.json``: one dict per N) and ``out``."""

def transit_flux(
    t_days: npt.ArrayLike,
    *,
    t0: float,
    per: float,
    rp: float,
    a: float,
    inc: float,
    u: Tuple[float, float],
    exp_time: float = 0.0,
    supersample: int = 1,
) -> npt.NDArray[np.float64]:
    """A limb-darkened transit's relative flux (circular orbit, quadratic law) at times in days; each value
    averaged over ``exp_time`` days sampled ``supersample`` times (batman's conventions)."""

def box_least_squares(
    t_days: npt.ArrayLike,
    flux: npt.ArrayLike,
    sigma: npt.ArrayLike,
    *,
    periods: npt.ArrayLike,
    durations: npt.ArrayLike,
) -> Optional[Dict[str, Any]]:
    """Box least squares: the most significant box (period, t0, duration, depth, depth_sigma, snr,
    points_in) over the trial periods and durations (days), or None."""

def transit(config: Optional[Config] = None, **fields: Any) -> Dict[str, Any]:
    """A transit-monitoring stare (``jsim transit``): keyword arguments set the ``[transit]`` fields
    (``target_hw``, ``duration_h``, ``depth``, ``comparisons``, …); returns the light curve's numpy arrays
    (``time`` in days, ``flux``, ``flux_raw``, ``flux_aperture``, ``flux_psf``, ``x``, ``y``, ``sky``,
    ``telemetry_x``, ``telemetry_y``, ``telemetry_sigma``, ``in_box``, the truth's ``injected``) and dicts
    ``readout``, ``precision``, ``budget``, ``recovery`` and ``detections``."""

def experiment(
    config: Optional[Config] = None,
    *,
    aces: Optional[Sequence[str]] = None,
    readouts: Optional[Sequence[str]] = None,
    mags: Optional[Sequence[float]] = None,
    countermeasures: Union[str, Sequence[str], None] = None,
    progress: Optional[Callable[[int, int], Any]] = None,
    as_frame: Optional[bool] = None,
) -> Any:
    """The paper's experiment (``jsim experiment``): rows as a pandas DataFrame when pandas is installed
    (``as_frame=None``), else a dict of arrays."""
