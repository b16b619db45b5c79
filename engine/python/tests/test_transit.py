"""The transit model (`jsim.transit_flux`, engine::scene::transit) against an independent implementation:
batman (Kreidberg 2015), whose quadratic law is Mandel & Agol's closed form with elliptic integrals, where
jsim integrates the occulted intensity numerically."""

import subprocess

import batman
import numpy as np
import pytest

import jsim


def batman_flux(t, *, t0, per, rp, a, inc, u, exp_time=0.0, supersample=1):
    p = batman.TransitParams()
    p.t0, p.per, p.rp, p.a, p.inc = t0, per, rp, a, inc
    p.ecc, p.w = 0.0, 90.0
    p.limb_dark, p.u = "quadratic", list(u)
    if exp_time > 0:
        m = batman.TransitModel(p, t, supersample_factor=supersample, exp_time=exp_time)
    else:
        m = batman.TransitModel(p, t)
    return m.light_curve(p)


# a JASMINE-like M-dwarf case (JASMINE-imagesim's example: Rp 3 R⊕ around 0.2 R☉, P 14 d), a grazing one, a
# giant planet with strong limb darkening, and a planet larger than a quarter of its star
CASES = [
    dict(t0=0.0, per=14.0, rp=0.137, a=40.0, inc=89.7, u=(0.1, 0.3)),
    dict(t0=0.3, per=3.0, rp=0.1, a=8.0, inc=83.0, u=(0.4, 0.25)),
    dict(t0=0.0, per=1.2, rp=0.3, a=4.0, inc=88.0, u=(0.6, 0.1)),
    dict(t0=0.0, per=5.0, rp=0.02, a=15.0, inc=90.0, u=(0.0, 0.0)),
]


@pytest.mark.parametrize("case", CASES)
def test_the_light_curve_matches_batman(case):
    span = 0.6 * case["per"] / np.pi * np.arcsin(min(1.0, 1.5 / case["a"]))
    t = case["t0"] + np.linspace(-span, span, 1500)
    ours = jsim.transit_flux(t, **case)
    ref = batman_flux(t, **case)
    depth = 1.0 - ref.min()
    assert depth > 1e-4
    # batman's own closed form is good to ≈ 1e-9 (its elliptic integrals); jsim's quadrature to 1e-10
    assert np.max(np.abs(ours - ref)) < 1e-7 * max(1.0, depth / 1e-2)


def test_an_exposure_is_the_mean_of_the_light_curve_over_it():
    # the reference: batman's instantaneous light curve averaged over each exposure by numpy (1000 midpoints;
    # batman's own supersampling takes the exposure's end points, np.linspace(-exp/2, exp/2, n), not midpoints)
    case = CASES[0]
    t = np.linspace(-0.15, 0.15, 200)
    exp = 500.0 / 86400.0
    offsets = ((np.arange(1000) + 0.5) / 1000 - 0.5) * exp
    ref = batman_flux((t[:, None] + offsets).ravel(), **case).reshape(len(t), -1).mean(axis=1)
    ours = jsim.transit_flux(t, **case, exp_time=exp, supersample=1000)
    assert np.max(np.abs(ours - ref)) < 1e-8
    # five samples per 500-s exposure: within 1 % of the 2 % depth (the ingress bends inside one sample)
    coarse = jsim.transit_flux(t, **case, exp_time=exp, supersample=5)
    assert np.max(np.abs(coarse - ref)) < 2e-4


@pytest.mark.parametrize(
    "bad, field",
    [(dict(per=0.0), "period_days"), (dict(rp=1.5), "rp_over_rs"), (dict(u=(1.2, 0.0)), "u1")],
)
def test_a_bad_parameter_is_named(bad, field):
    case = {**CASES[0], **bad}
    with pytest.raises(ValueError, match=field):
        jsim.transit_flux(np.zeros(3), **case)


def test_box_least_squares_finds_what_astropy_finds():
    # an outside tool: astropy's BoxLeastSquares (Kovács et al. 2002 as well) on the same light curve, its
    # objective the same signal-to-noise; both must find the injected period, and agree on the depth within
    # the depth's error
    from astropy.timeseries import BoxLeastSquares

    rng = np.random.default_rng(11)
    t = np.sort(rng.uniform(0, 12, 5000))
    sigma = np.full_like(t, 8e-4)
    case = dict(t0=1.3, per=3.37, rp=0.04, a=12.0, inc=90.0, u=(0.3, 0.2))
    f = jsim.transit_flux(t, **case) + rng.normal(0, 8e-4, t.size)
    periods = np.linspace(1.5, 5.0, 3000)
    durations = np.array([0.06, 0.09, 0.12])
    ours = jsim.box_least_squares(t, f, sigma, periods=periods, durations=durations)
    ref = BoxLeastSquares(t, f, dy=sigma).power(periods, durations, objective="snr")
    k = int(np.argmax(ref.power))
    assert abs(ours["period"] - case["per"]) < 0.01
    assert abs(ref.period[k] - case["per"]) < 0.01
    assert abs(ours["depth"] - ref.depth[k]) < 3 * ref.depth_err[k]
    assert ours["snr"] > 10
    assert jsim.box_least_squares(t[:0], f[:0], sigma[:0], periods=periods, durations=durations) is None
    with pytest.raises(ValueError, match="one value each"):
        jsim.box_least_squares(t, f[:-1], sigma, periods=periods, durations=durations)


# ---------------------------------------------------------------------------------------------------------
# jsim.transit: a stare, its light curve as numpy arrays and as the CLI's astropy table
# ---------------------------------------------------------------------------------------------------------

STARE = dict(comparisons=5, field_radius_px=150.0)


def test_a_stare_gives_numpy_light_curves_and_recovers_its_transit(cfg):
    r = jsim.transit(cfg, duration_h=3.0, depth=0.01, **STARE)
    n = len(r["time"])
    assert n == int(3.0 * 3600 / 12.6)
    for k in ["flux", "flux_raw", "flux_aperture", "flux_psf", "x", "y", "telemetry_sigma", "injected"]:
        assert isinstance(r[k], np.ndarray) and r[k].shape == (n,), k
    # the injected transit is Mandel & Agol's, averaged over each 12.5-s plate: batman's, independently
    t0 = 1.5 / 24
    inc = 90.0
    ref = batman_flux(r["time"], t0=t0, per=14.0, rp=0.1, a=71.5, inc=inc, u=(0.1, 0.3),
                      exp_time=12.5 / 86400, supersample=7)
    # each plate's time is its integration's middle; batman averages 7 instants across it as jsim does
    assert np.max(np.abs(r["injected"] - ref)) < 1e-6
    rec = r["recovery"]
    assert rec is not None and rec["overlaps_injected"]
    assert abs(rec["depth"] - rec["injected_depth"]) < 3 * rec["depth_sigma"], rec


def test_the_cli_writes_the_same_light_curve_as_an_astropy_table(cfg, jsim_bin, tmp_path):
    from astropy.table import Table

    sets = [f"--set={k}={v}" for k, v in {
        "instrument.detector_px": 512, "instrument.photosensitive_px": 496, "readout.channels": 4,
        "readout.channel_width_px": 128, "optics.pupil_samples": 128, "optics.psf_oversampling": 8,
        "optics.psf_radius_px": 10, "band.wavelength_step_um": 0.05, "fidelity.subpixels": 4,
        "fidelity.backend": '"cpu"', "ace.span_s": 120.0, "transit.comparisons": 5,
        "transit.field_radius_px": 150.0,
    }.items()]
    out = tmp_path / "stare"
    subprocess.run([jsim_bin, "transit", "--instrument", "design", "--hours", "0.3", "--depth", "0", *sets,
                    "--out", str(out)],
                   check=True, capture_output=True)
    t = Table.read(out / "lightcurve.ecsv")
    assert str(t["time"].unit) == "d" and str(t["telemetry_sigma"].unit) == "mas"
    r = jsim.transit(cfg, duration_h=0.3, depth=0.0, **STARE)
    assert len(t) == len(r["time"])
    np.testing.assert_allclose(np.asarray(t["flux"]), r["flux"], rtol=1e-12)
    assert t.meta["comparisons"] == "5"


def test_bad_stares_are_value_errors_naming_the_field(cfg):
    with pytest.raises(ValueError, match="transit.period_days"):
        jsim.transit(cfg, duration_h=3.0, depth=0.003, period_days=0.0, **STARE)
    with pytest.raises(ValueError, match="transit.exposure_s"):
        jsim.transit(cfg, target_hw=6.0, exposure_s=12.5, duration_h=0.1, depth=0.0, **STARE)
    with pytest.raises(ValueError, match="no such field"):
        jsim.transit(cfg, colour=1.0)


def test_photutils_on_the_written_products_gives_the_same_light_curve(jsim_bin, tmp_path):
    # the products as files (every window of every plate, the calibration flat over each window) measured by
    # an outside tool: photutils' aperture photometry at jsim's radius, around photutils' own centroids,
    # the sky from the same annulus' median — the differential light curve jsim measured, plate for plate
    from astropy.io import fits
    from astropy.table import Table
    from photutils.aperture import CircularAnnulus, CircularAperture, aperture_photometry
    from photutils.centroids import centroid_com

    sets = [f"--set={k}={v}" for k, v in {
        "instrument.detector_px": 512, "instrument.photosensitive_px": 496, "readout.channels": 4,
        "readout.channel_width_px": 128, "optics.pupil_samples": 128, "optics.psf_oversampling": 8,
        "optics.psf_radius_px": 10, "band.wavelength_step_um": 0.05, "fidelity.subpixels": 4,
        "fidelity.backend": '"cpu"', "ace.span_s": 120.0, "transit.comparisons": 5,
        "transit.field_radius_px": 150.0, "transit.aperture_px": 6.0, "transit.decorrelate": '"none"',
    }.items()]
    out = tmp_path / "stare"
    subprocess.run([jsim_bin, "transit", "--instrument", "design", "--hours", "0.4", "--depth", "0", "--hw", "8", *sets,
                    "--write-products", "--out", str(out)], check=True, capture_output=True)
    lc = Table.read(out / "lightcurve.ecsv")
    with fits.open(out / "windows.fits") as h:
        g, bias, nstars = h[0].header["GAIN"], h[0].header["BIAS"], h[0].header["NSTARS"]
        fluxes = []
        for k in range(nstars):
            cube, flat = h[f"STAR_{k}"].data.astype(float), h[f"FLAT_{k}"].data.astype(float)
            n = flat.shape[0]
            f = []
            for p in range(cube.shape[0] // n):
                e = (cube[p * n:(p + 1) * n] - bias) * g / flat
                # the star where the data put it: its brightest pixel, then the centroid about it
                cy0, cx0 = np.unravel_index(np.argmax(e), e.shape)
                cx0, cy0 = min(max(cx0, 3), n - 4), min(max(cy0, 3), n - 4)
                box = e[cy0 - 3:cy0 + 4, cx0 - 3:cx0 + 4]
                cx, cy = centroid_com(box - np.median(e))
                xy = (cx0 - 3 + cx, cy0 - 3 + cy)
                sky = np.median(CircularAnnulus(xy, 11.0, 14.0).to_mask(method="center").get_values(e))
                ap = CircularAperture(xy, 6.0)
                f.append(aperture_photometry(e, ap, method="exact")["aperture_sum"][0] - sky * ap.area)
            fluxes.append(np.array(f))
    diff = fluxes[0] / np.sum(fluxes[1:], axis=0)
    diff /= np.median(diff)
    ours = np.asarray(lc["flux_aperture"])
    assert len(diff) == len(ours)
    # the same plates' noise: nearly the same values, the same scatter
    assert np.corrcoef(diff, ours)[0, 1] > 0.98
    assert abs(np.std(diff) / np.std(ours) - 1) < 0.05
