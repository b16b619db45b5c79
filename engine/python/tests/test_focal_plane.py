"""The quad focal plane's multi-extension FITS against astropy (issue #15's acceptance): each array's WCS
(RA---TAN-SIP, the example distortion) reads without warnings and round-trips pixel → sky → pixel, stars
land where astropy's WCS puts their catalogue RA/Dec, the arrays sit in their places on the sky, and every
star of the scene is accounted for in the primary header."""

import subprocess
import warnings
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.wcs import WCS

from conftest import SMALL

ENGINE = Path(__file__).resolve().parents[2]
SIP_EXAMPLE = ENGINE / "configs" / "focal_plane_sip.toml"
N = SMALL["instrument.detector_px"]
GAP = 60.0


def simulate(jsim_bin, out, scene, *extra):
    sets = [f"{k}={v}" if not isinstance(v, str) else f'{k}="{v}"' for k, v in SMALL.items()]
    sets += [f"focal_plane.gap_px={GAP}", "fidelity.images=1", *extra]
    cmd = [jsim_bin, "simulate", "--config", str(SIP_EXAMPLE), "--scene", scene, "--ace", "gaussian"]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd + ["--out", str(out)], check=True, capture_output=True, text=True)
    return out / "fp_000.fits"


def array_wcs(hdul, k):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return WCS(hdul[f"ARRAY{k}"].header)


def test_each_array_wcs_reads_without_warnings_and_round_trips(jsim_bin, tmp_path):
    path = simulate(jsim_bin, tmp_path / "bulge", "bulge", "scene.bulge.density_per_arcmin2=20")
    rng = np.random.default_rng(3)
    with fits.open(path) as h:
        p = h[0].header
        assert p["NARRAYS"] == 4
        # every star of the scene is accounted for, and the truth holds those on photosensitive pixels
        parts = p["NDUPLIC"] + p["NPHOTO"] + p["NBORDER"] + p["NGAP"] + p["NOFF"]
        assert parts == p["NCATALOG"] and p["NGAP"] > 0 and p["NPHOTO"] > 500
        truth = h["TRUTH"].data
        assert len(truth) == p["NPHOTO"]
        assert set(np.unique(truth["array"])) == {1, 2, 3, 4}
        for k in range(1, 5):
            w = array_wcs(h, k)
            assert w.wcs.ctype[0] == "RA---TAN-SIP" and w.sip is not None
            assert h[f"ARRAY{k}"].data.shape == (N, N) and h[f"DQ{k}"].data.shape == (N, N)
            # pixel → sky → pixel through astropy's own inverse (it iterates on A, B): < 1e-6 px
            pix = rng.uniform(-0.5, N - 0.5, size=(200, 2))
            back = w.all_world2pix(w.all_pix2world(pix, 0), 0, tolerance=1e-10, maxiter=100)
            assert np.abs(back - pix).max() < 1e-6
            # the truth's RA, Dec are astropy's sky positions of the truth's pixels
            mine = truth[truth["array"] == k]
            sky = w.all_pix2world(np.column_stack([mine["x"], mine["y"]]), 0)
            cosd = np.cos(np.radians(sky[:, 1]))
            err_uas = np.hypot((mine["ra_deg"] - sky[:, 0]) * cosd, mine["dec_deg"] - sky[:, 1]) * 3.6e9
            assert err_uas.max() < 1.0


def test_stars_land_where_astropy_puts_their_catalogue_positions(jsim_bin, tmp_path):
    # a catalogue drawn over the focal plane, in RA/Dec; the truth's array pixel of each star against
    # astropy's all_world2pix of the catalogue position on that array: < 1e-3 px
    ra0, dec0 = 266.4168, -29.0078
    half_deg = (N + GAP / 2) * 472.1 / 3.6e6
    rng = np.random.default_rng(11)
    n = 400
    dec = dec0 + rng.uniform(-half_deg, half_deg, n)
    ra = ra0 + rng.uniform(-half_deg, half_deg, n) / np.cos(np.radians(dec0))
    cat = tmp_path / "stars.csv"
    rows = ["ra,dec,hw,j_h"] + [f"{a:.12f},{d:.12f},14.0,2.0" for a, d in zip(ra, dec)]
    cat.write_text("\n".join(rows) + "\n")
    path = simulate(jsim_bin, tmp_path / "cat", str(cat))
    with fits.open(path) as h:
        truth = h["TRUTH"].data
        assert len(truth) > 200
        for k in range(1, 5):
            w = array_wcs(h, k)
            mine = truth[truth["array"] == k]
            ids = mine["id"].astype(int)
            pix = w.all_world2pix(np.column_stack([ra[ids], dec[ids]]), 0, tolerance=1e-10, maxiter=100)
            err = np.hypot(pix[:, 0] - mine["x"], pix[:, 1] - mine["y"])
            assert err.max() < 1e-3, (k, err.max())
            # and each such star is on the array's photosensitive pixels by astropy's reckoning too
            b = (N - SMALL["instrument.photosensitive_px"]) / 2
            assert ((pix >= b - 0.5) & (pix < N - b - 0.5)).all()


def test_the_arrays_sit_in_their_places_on_the_sky(jsim_bin, tmp_path):
    # array 1 lower left, 2 lower right, 3 upper left, 4 upper right on a north-up, east-left sky (PA 0)
    path = simulate(jsim_bin, tmp_path / "layout", "bulge", "scene.bulge.density_per_arcmin2=0")
    with fits.open(path) as h:
        c = (N - 1) / 2
        centre = {k: array_wcs(h, k).all_pix2world([[c, c]], 0)[0] for k in range(1, 5)}
        rotation = {k: h[f"ARRAY{k}"].header["ROTATION"] for k in range(1, 5)}
    assert rotation == {1: 0.0, 2: 90.0, 3: 180.0, 4: 270.0}
    east = lambda a, b: (a[0] - b[0]) * np.cos(np.radians(b[1])) * 3.6e6 / 472.1  # noqa: E731
    north = lambda a, b: (a[1] - b[1]) * 3.6e6 / 472.1  # noqa: E731
    step = N + GAP  # pixels between neighbouring array centres (the distortion moves them < 1 px)
    assert abs(east(centre[2], centre[1]) + step) < 2.0 and abs(north(centre[2], centre[1])) < 2.0
    assert abs(north(centre[3], centre[1]) - step) < 2.0 and abs(east(centre[3], centre[1])) < 2.0
    assert abs(east(centre[4], centre[3]) + step) < 2.0
