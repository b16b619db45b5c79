"""Python and the CLI give the same files and the same analysis: FITS round trips through astropy, the
header cards, and `analyze` through Python against `jsim analyze` on the written file."""

import json
import subprocess

import numpy as np
import pytest
from astropy.io import fits

import jsim


def test_write_fits_reads_back_in_astropy_as_the_image(exposure, tmp_path):
    path = tmp_path / "img.fits"
    exposure.write_fits(path)
    with fits.open(path) as h:
        assert h[0].data.dtype == exposure.image.dtype
        assert h[0].data.shape == exposure.image.shape
        np.testing.assert_array_equal(h[0].data, exposure.image)
        np.testing.assert_array_equal(h["DQ"].data, exposure.dq)
        truth = h["TRUTH"].data
        for name, col in exposure.truth.items():
            np.testing.assert_array_equal(truth[name], col)
        for key, value in exposure.header.items():
            got = h[0].header[key]
            if isinstance(value, float):
                assert got == np.float64(value) or abs(got - value) <= 1e-14 * abs(value), key
            else:
                assert got == value, key
        assert h[0].header["SEED"] == exposure.config.get("seed")
        assert h[0].header["IMAGEIDX"] == exposure.index


def test_the_image_wcs_reads_in_astropy_without_warnings(exposure, tmp_path):
    import warnings

    from astropy.wcs import WCS

    path = tmp_path / "img.fits"
    exposure.write_fits(path)
    with fits.open(path) as h, warnings.catch_warnings():
        warnings.simplefilter("error")
        w = WCS(h[0].header)
    n = exposure.image.shape[0]
    cfg = exposure.config
    # the optical axis is the array centre, at the apparent place of the configured axis (astropy's GCRS
    # from the header's spacecraft state: < 0.01 mas); the pixel scale is the plate scale; north is +y,
    # east is −x
    from test_focal_plane import apparent_place_by_astropy

    ra, dec = w.all_pix2world([[(n - 1) / 2, (n - 1) / 2]], 0)[0]
    hd = fits.getheader(path)
    app = apparent_place_by_astropy(
        hd, *[np.array([v]) for v in (cfg.get("sky.ra_deg"), cfg.get("sky.dec_deg"), 0.0, 0.0, 1e-4)]
    )
    err_mas = np.hypot((ra - app[0][0]) * np.cos(np.radians(dec)), dec - app[1][0]) * 3.6e6
    assert err_mas < 0.01, err_mas
    (x0, y0), (xn, yn), (xe, ye) = w.all_world2pix(
        [[ra, dec], [ra, dec + 0.01], [ra + 0.01, dec]], 0
    )
    # every star's RA, Dec in the truth is astropy's sky position of its pixel position (< 1 µas)
    t = exposure.truth
    sky = w.all_pix2world(np.column_stack([t["x"], t["y"]]), 0)
    cosd = np.cos(np.radians(sky[:, 1]))
    err_uas = np.hypot((t["ra_deg"] - sky[:, 0]) * cosd, t["dec_deg"] - sky[:, 1]) * 3.6e9
    assert err_uas.max() < 1.0, err_uas.max()
    scale_mas = exposure.header["PLTSCALE"]
    assert abs((yn - y0) - 36000.0 / scale_mas) < 1e-3 and abs(xn - x0) < 1e-6
    assert xe < x0 and abs(ye - y0) < 0.1


def test_time_stamps_and_instrument_products_read_in_astropy_without_warnings(exposure, tmp_path):
    import warnings

    from astropy.table import Table
    from astropy.time import Time
    from erfa import ErfaWarning

    path = tmp_path / "img.fits"
    exposure.write_fits(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with fits.open(path) as h:
            h.verify("exception")
            hd = h[0].header
            assert (hd["TELESCOP"], hd["FILTER"], hd["TIMESYS"]) == ("JASMINE", "Hw", "UTC")
        # DATE-OBS (to the millisecond) and MJD-OBS are the same instant: observation.start_utc (2031-03-21,
        # MJD 62946) + TSTART; MJD-TDB is that instant in TDB (astropy's own conversion; ERFA calls a 2031
        # date's leap seconds "dubious", as they are: that warning alone is let through)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ErfaWarning)
            t = Time(hd["DATE-OBS"], scale="utc")
            tdb_mjd = t.tdb.mjd
        assert abs(t.mjd - hd["MJD-OBS"]) * 86400 < 1e-3
        assert abs((hd["MJD-OBS"] - 62946.0) * 86400 - hd["TSTART"]) < 1e-3
        assert abs(tdb_mjd - hd["MJD-TDB"]) * 86400 < 1e-3
        for name in ["flat_cal.fits", "psf_model.fits", f"telemetry_{exposure.index:03d}.fits"]:
            with fits.open(tmp_path / name) as h:
                h.verify("exception")
        with fits.open(tmp_path / "flat_cal.fits") as h:
            assert 0.0 < h[0].header["FLATERR"] < 1.0
            assert abs(np.mean(h[0].data) - 1.0) < 0.05
        att = Table.read(tmp_path / f"telemetry_{exposure.index:03d}.fits", hdu="ATTITUDE")
        assert att.colnames == ["T_S", "ATT_X_MAS", "ATT_Y_MAS"] and len(att) > 100
        assert [str(att[c].unit) for c in att.colnames] == ["s", "mas", "mas"]
        # every table column states its unit (TUNITn, '' for a dimensionless one); the primary has no EXTNAME
        truth = Table.read(path, hdu="TRUTH")
        assert str(truth["x"].unit) == "pix" and str(truth["mag_hw"].unit) == "mag"
        with fits.open(path) as h:
            assert "EXTNAME" not in h[0].header
            assert h[0].header["DETECTOR"] == "NIR1"
            cols = h["TRUTH"].header["TFIELDS"]
            assert all(f"TUNIT{i}" in h["TRUTH"].header for i in range(1, cols + 1))
        ref = Table.read(tmp_path / "refcat.csv", format="ascii.csv")
        assert {"ra_deg", "dec_deg", "x_px", "y_px", "hw", "sigma_mas"} <= set(ref.colnames)


def test_the_image_is_handed_over_without_a_copy(exposure):
    img = exposure.image
    assert not img.flags.owndata, "the array must wrap the engine's buffer"
    assert img.base is not None
    assert img is exposure.image, "the same array every time"
    assert img.flags.c_contiguous


def read_catalogue(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: data[name] for name in data.dtype.names}


def assert_python_is_the_cli(jsim_bin, image, cm, tmp_path, py):
    """`jsim analyze --image image --countermeasure cm` run into tmp_path, and the Python analysis `py` of the
    same: the same catalogue bit for bit, the same accuracy, bound and counts, the same assumptions. Returns
    the CLI's summary."""
    out = tmp_path / f"an-{cm.replace(':', '_').replace('@', '_')}"
    subprocess.run(
        [jsim_bin, "analyze", "--image", str(image), "--countermeasure", cm, "--out", str(out)],
        check=True,
        capture_output=True,
    )
    cli = read_catalogue(out / "catalogue.csv")
    summary = json.loads((out / "summary.json").read_text())
    assert set(cli) == set(py.catalogue)
    for name in cli:
        np.testing.assert_array_equal(py.catalogue[name], cli[name], err_msg=f"{cm}: {name}")
    for key in ["accuracy_mas", "accuracy_x_mas", "crlb_median_mas", "n_used", "n_detected"]:
        assert py.summary[key] == summary["report"][key], (cm, key)
    assert py.assumptions == summary["assumptions"], cm
    return summary


def test_analyze_in_python_equals_jsim_analyze_on_the_file(session, exposure, tmp_path, jsim_bin):
    path = tmp_path / "img.fits"
    exposure.write_fits(path)
    for cm in ["none", "plate-poly:3@oracle"]:
        py = session.analyze(exposure, countermeasure=cm)
        summary = assert_python_is_the_cli(jsim_bin, path, cm, tmp_path, py)
        assert summary["assumptions"] == []
        assert py.summary["countermeasure"] == cm


def test_an_array_with_its_header_analyses_as_the_exposure(session, exposure):
    by_exposure = session.analyze(exposure, countermeasure="none")
    by_array = session.analyze(
        np.asarray(exposure.image, dtype=np.float64),
        exposure.header,
        dq=exposure.dq,
        truth=exposure.truth,
        config=exposure.config,
        flat=exposure.calibration_flat[0],
        flat_error=exposure.calibration_flat[1],
    )
    for name, col in by_exposure.catalogue.items():
        np.testing.assert_array_equal(by_array.catalogue[name], col, err_msg=name)
    assert by_array.summary == by_exposure.summary


def test_an_array_without_a_header_says_what_it_assumed(session, exposure):
    a = session.analyze(exposure.image.astype(np.float32), truth=exposure.truth)
    joined = " ".join(a.assumptions)
    for key in ["GAIN", "RDNOISE", "BIASADU", "PLTSCALE", "CONFIG"]:
        assert key in joined, key
    assert np.isfinite(a.summary["accuracy_mas"])


def test_the_psf_is_the_cli_psf(session, tmp_path, jsim_bin):
    table, cells_per_px = session.psf()
    n = table.shape[0]
    assert table.shape == (n, n) and n % 2 == 1
    assert np.unravel_index(np.argmax(table), table.shape) == (n // 2, n // 2)
    # encircled energy inside a ±10 px table of an f/… telescope: most, never all, of the light
    assert 0.9 < table.sum() < 1.0
    toml = tmp_path / "cfg.toml"
    toml.write_text(session.config.to_toml())
    subprocess.run(
        [jsim_bin, "psf", "--config", str(toml), "--out", str(tmp_path / "psf.fits")],
        check=True,
        capture_output=True,
    )
    with fits.open(tmp_path / "psf.fits") as h:
        np.testing.assert_array_equal(h[0].data, table)
        assert h[0].header["OVERSAMP"] == cells_per_px


def test_experiment_rows_equal_the_cli(cfg, tmp_path, jsim_bin):
    rows = jsim.experiment(
        cfg, aces=["gaussian"], mags=[13.0], countermeasures="none,plate-poly:3", as_frame=False
    )
    assert list(rows["countermeasure"]) == ["none", "plate-poly:3"]
    toml = tmp_path / "cfg.toml"
    toml.write_text(cfg.to_toml())
    out = tmp_path / "exp"
    subprocess.run(
        [jsim_bin, "experiment", "--config", str(toml), "--aces", "gaussian", "--mags", "13",
         "--countermeasures", "none,plate-poly:3", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    cli = np.genfromtxt(out / "experiment.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    for k in range(2):
        for key in ["accuracy_mas", "sem_mas", "crlb_mas", "predicted_mas"]:
            assert rows[key][k] == cli[key][k], key
        assert rows["n_images"][k] == cli["n_images"][k] == 3


def test_a_file_with_its_products_analyses_in_python_as_in_jsim_analyze(tmp_path, jsim_bin):
    # a realistic-ACE image written by `jsim simulate` with every product beside it (the calibration flat, the
    # reference catalogue, the telemetry, the design model PSF): `Session.analyze_file` reads them as
    # `jsim analyze` does, and gives its catalogue bit for bit — with the telemetry forward model (telemetry
    # and model PSF) and a catalogue-referenced plate model (refcat)
    from conftest import SMALL, small_config

    sets = [f"{k}={v}" if not isinstance(v, str) else f'{k}="{v}"' for k, v in SMALL.items()]
    sets += ['ace.case="realistic"', "fidelity.images=1"]
    cmd = [jsim_bin, "simulate", "--out", str(tmp_path / "sim")]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True, capture_output=True)
    image = tmp_path / "sim" / "img_000.fits"
    for name in ["flat_cal.fits", "refcat.csv", "telemetry_000.fits", "psf_model.fits"]:
        assert (tmp_path / "sim" / name).exists(), name
    session = jsim.Session(small_config(), backend="cpu")
    for cm in ["telemetry-model", "plate-poly:3@catalogue"]:
        assert_python_is_the_cli(jsim_bin, image, cm, tmp_path, session.analyze_file(image, countermeasure=cm))
    # the array form with the same products gives the file form's measurements bit for bit: the image and its
    # header as astropy reads them, the flat as an array, the other products as files
    sim = tmp_path / "sim"
    with fits.open(image) as h, fits.open(sim / "flat_cal.fits") as f:
        data = h[0].data.astype(np.float32)
        header = {k: v for k, v in h[0].header.items() if k and k not in ("COMMENT", "HISTORY")}
        dq = np.ascontiguousarray(h["DQ"].data.astype(np.uint8))
        flat, flat_error = f[0].data.astype(np.float32), float(f[0].header["FLATERR"])
    products = dict(refcat=sim / "refcat.csv", model_psf=sim / "psf_model.fits", telemetry=sim / "telemetry_000.fits")
    measured = ["x", "y", "flux_e", "sky_e", "crlb_x_mas", "crlb_y_mas", "flags"]
    for cm in ["telemetry-model", "plate-poly:3@catalogue"]:
        a = session.analyze(data, header, dq=dq, flat=flat, flat_error=flat_error, countermeasure=cm, **products)
        b = session.analyze_file(image, countermeasure=cm)
        for name in measured:
            np.testing.assert_array_equal(a.catalogue[name], b.catalogue[name], err_msg=f"{cm}: {name}")
    # without the telemetry the forward model has nothing to correct with, and says so
    bare = session.analyze(data, header, dq=dq, flat=flat, flat_error=flat_error, countermeasure="telemetry-model")
    assert any("no attitude telemetry" in a for a in bare.assumptions)
    # a telemetry of another exposure than the header's is refused by name
    with pytest.raises(OSError, match="telemetry of exposure 0"):
        session.analyze(data, dict(header, IMAGEIDX=1), dq=dq, flat=flat, flat_error=flat_error, **products)
    # a focal-plane file is refused by name
    fp = tmp_path / "fp"
    quad = [s for s in sets if not s.startswith("ace.case")] + [
        'focal_plane.layout="quad"', "scene.bulge.density_per_arcmin2=0", 'ace.case="gaussian"'
    ]
    subprocess.run(
        [jsim_bin, "simulate", "--scene", "bulge", "--out", str(fp)] + [a for s in quad for a in ("--set", s)],
        check=True,
        capture_output=True,
    )
    with pytest.raises(ValueError, match="focal-plane"):
        session.analyze_file(fp / "fp_000.fits")
