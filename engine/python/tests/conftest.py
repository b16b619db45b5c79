"""Shared fixtures: a small configuration (the engine's testkit::small_config: the instrument as designed, a test
switching on the deviations it tests) and the jsim binary."""

import os
import shutil

import pytest

import jsim

SMALL = {
    "instrument.detector_px": 512,
    "instrument.photosensitive_px": 496,
    "readout.channels": 4,
    "readout.channel_width_px": 128,
    "scene.grid_n": 8,
    "scene.grid_spacing_px": 56.0,
    "optics.pupil_samples": 128,
    "optics.psf_oversampling": 8,
    "optics.psf_radius_px": 10,
    "band.wavelength_step_um": 0.05,
    "fidelity.subpixels": 4,
    "fidelity.images": 3,
    "fidelity.backend": "cpu",
    "ace.span_s": 120.0,
}


def small_config(**changes):
    cfg = jsim.Config.default().as_designed()
    for k, v in {**SMALL, **changes}.items():
        cfg.set(k, v)
    return cfg


@pytest.fixture
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def session():
    return jsim.Session(small_config(), backend="cpu")


@pytest.fixture(scope="module")
def exposure(session):
    return session.simulate(image=1)


@pytest.fixture(scope="session")
def jsim_bin():
    """The jsim CLI: JSIM_BIN (set by engine/tests/python.rs to the binary cargo built), else on PATH."""
    path = os.environ.get("JSIM_BIN") or shutil.which("jsim")
    if not path:
        if os.environ.get("CI"):
            pytest.fail("JSIM_BIN is not set and no jsim on PATH: the CLI comparisons cannot run")
        pytest.skip("no jsim binary (set JSIM_BIN)")
    return path
