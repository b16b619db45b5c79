"""An image jsim did not make: written by engine/python/examples/crowded_image.py (numpy + astropy, a
Gaussian PSF), analysed in crowded mode by `jsim analyze` and by `Session.analyze` alike, and scored apart by
`jsim score` and `jsim.score` alike."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from astropy.io import fits

import jsim

SCRIPT = os.path.join(os.path.dirname(__file__), "..", "examples", "crowded_image.py")


@pytest.fixture(scope="module")
def outside(tmp_path_factory):
    d = tmp_path_factory.mktemp("outside")
    subprocess.run(
        [sys.executable, SCRIPT, "--stars", "1500", "--size", "256", "--mag-min", "11", "--mag-max", "16",
         "--seed", "5", "--out", str(d)],
        check=True,
        capture_output=True,
    )
    return d


def read_csv(path):
    with open(path) as f:
        names = f.readline().strip().split(",")
        rows = [line.strip().split(",") for line in f if line.strip()]
    return {n: np.array([float(r[i]) for r in rows]) for i, n in enumerate(names)}


def test_the_outside_image_reads_as_another_tool_wrote_it(outside):
    with fits.open(outside / "image.fits") as h:
        assert len(h) == 1 and h[0].data.shape == (256, 256)
        assert h[0].header["ORIGIN"].startswith("crowded_image.py")
        for key in ["GAIN", "RDNOISE", "BIASADU", "EXPTIME", "SATURATE", "PLTSCALE"]:
            assert key in h[0].header, key


def test_cli_and_python_analyse_it_in_crowded_mode_and_score_it_alike(outside, jsim_bin, tmp_path):
    an = tmp_path / "an"
    out = subprocess.run(
        [jsim_bin, "analyze", "--image", str(outside / "image.fits"), "--out", str(an)],
        check=True,
        capture_output=True,
        text=True,
    )
    assert "no accuracy" in out.stdout
    summary = json.loads((an / "summary.json").read_text())
    assert summary["report"]["crowded"] is True
    assert summary["report"]["accuracy_mas"] is None  # no truth: absent, never 0

    with fits.open(outside / "image.fits") as h:
        data = np.asarray(h[0].data, dtype=np.float32)
        header = {k: h[0].header[k] for k in ["GAIN", "RDNOISE", "BIASADU", "EXPTIME", "SATURATE", "PLTSCALE"]}
    py = jsim.Session(backend="cpu").analyze(data, header)
    assert py.summary["crowded"] is True
    assert py.summary["accuracy_mas"] is None  # absent, as in summary.json
    cli = read_csv(an / "catalogue.csv")
    np.testing.assert_array_equal(py.catalogue["x"], cli["x"])
    np.testing.assert_array_equal(py.catalogue["y"], cli["y"])

    sc = tmp_path / "score"
    subprocess.run(
        [jsim_bin, "score", "--catalogue", str(an / "catalogue.csv"), "--truth", str(outside / "truth.csv"),
         "--out", str(sc)],
        check=True,
        capture_output=True,
    )
    cli_score = json.loads((sc / "score.json").read_text())
    truth = read_csv(outside / "truth.csv")
    s = jsim.score(
        {"x": py.catalogue["x"], "y": py.catalogue["y"], "flags": py.catalogue["flags"]},
        truth,
        plate_scale_mas=header["PLTSCALE"],
    )
    assert [b["n_matched"] for b in s["bins"]] == [b["n_matched"] for b in cli_score["bins"]]
    assert s["false_detections"] == cli_score["false_detections"]
    assert s["all"]["accuracy_mas"] == pytest.approx(cli_score["all"]["accuracy_mas"], rel=1e-12)
    # the crowded analysis finds nearly every star of Hw 11–14 in a field where most have neighbours
    bright = [b for b in s["bins"] if b["mag_hi"] <= 14.0]
    found = sum(b["n_matched"] for b in bright) / sum(b["n_true"] for b in bright)
    assert found > 0.9, s["bins"]


def test_score_refuses_what_it_cannot_use():
    with pytest.raises(ValueError, match="mag"):
        jsim.score({"x": [1.0], "y": [1.0]}, {"x": [1.0], "y": [1.0]}, plate_scale_mas=471.0)
    with pytest.raises(ValueError, match="match_radius_px"):
        jsim.score({"x": [1.0], "y": [1.0]}, {"x": [1.0], "y": [1.0], "mag": [12.0]}, plate_scale_mas=471.0,
                   match_radius_px=0.0)
    with pytest.raises(ValueError, match="y"):
        jsim.score({"x": [1.0, 2.0], "y": [1.0]}, {"x": [1.0], "y": [1.0], "mag": [12.0]}, plate_scale_mas=471.0)
    s = jsim.score({"x": [1.0], "y": [1.0]}, {"x": [1.0], "y": [1.0], "mag": [12.0]}, plate_scale_mas=471.0)
    assert s["all"]["accuracy_mas"] is None  # one star: no accuracy, never 0
