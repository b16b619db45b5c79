"""The quad focal plane's multi-extension FITS against astropy (issue #15's acceptance): each array's WCS
(RA---TAN-SIP, the example distortion) reads without warnings and round-trips pixel → sky → pixel, stars
land where astropy's WCS puts their apparent place at the exposure's epoch (astropy's own: proper motion,
parallax, deflection, aberration from the header's spacecraft state), the arrays sit in their places on the
sky, and every star of the scene is accounted for in the primary header.

The header's WCS is the design's (every array at its nominal place); these tests check where the simulation puts
the stars, so they ask for the as-built instrument's WCS in the header by name (ORACLE, the control
`as_built.knowledge = "as-built"`), and the last checks that without it the header is the design's."""

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
# the oracle control: the header's WCS is the as-built instrument's (the arrays as assembled)
ORACLE = 'as_built.knowledge="as-built"'


def simulate(jsim_bin, out, scene, *extra):
    sets = [f"{k}={v}" if not isinstance(v, str) else f'{k}="{v}"' for k, v in SMALL.items()]
    sets += [f"focal_plane.gap_px={GAP}", "fidelity.images=1", *extra]
    cmd = [jsim_bin, "simulate", "--instrument", "design", "--config", str(SIP_EXAMPLE), "--scene", scene,
           "--ace", "gaussian"]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd + ["--out", str(out)], check=True, capture_output=True, text=True)
    return out / "fp_000.fits"


def array_wcs(hdul, k):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return WCS(hdul[f"ARRAY{k}"].header)


def test_each_array_wcs_reads_without_warnings_and_round_trips(jsim_bin, tmp_path):
    path = simulate(jsim_bin, tmp_path / "bulge", "bulge", "scene.bulge.density_per_arcmin2=20", ORACLE)
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


def apparent_place_by_astropy(header, ra, dec, pmra, pmdec, parallax):
    """The apparent place astropy gives the catalogue stars at the header's instant, seen from the header's
    spacecraft position and velocity (GCRS with obsgeoloc/obsgeovel): proper motion and parallax, light
    deflection by the Sun, aberration — jsim's truth must agree with it."""
    import astropy.units as u
    from astropy.coordinates import GCRS, CartesianRepresentation, Distance, SkyCoord
    from astropy.time import Time

    t = Time(header["APPMJD"], format="mjd", scale="utc")
    cat = SkyCoord(
        ra=ra * u.deg, dec=dec * u.deg, pm_ra_cosdec=pmra * u.mas / u.yr, pm_dec=pmdec * u.mas / u.yr,
        distance=Distance(parallax=parallax * u.mas), radial_velocity=np.zeros_like(ra) * u.km / u.s,
        obstime=Time(header["CATEPOCH"], format="jyear", scale="tdb"),
    )
    pos = CartesianRepresentation([header[f"SCGCRS{a}"] for a in "XYZ"] * u.km)
    vel = CartesianRepresentation([header[f"SCGCRSV{a}"] for a in "XYZ"] * u.km / u.s)
    app = cat.apply_space_motion(new_obstime=t).transform_to(GCRS(obstime=t, obsgeoloc=pos, obsgeovel=vel))
    return app.ra.deg, app.dec.deg


def test_stars_land_at_their_apparent_place_by_astropy(jsim_bin, tmp_path):
    # a catalogue drawn over the focal plane, in RA/Dec at the Gaia DR3 epoch with bulge-like motions; the
    # exposure in the autumn season of 2032: astropy's apparent place of each star through astropy's WCS
    # of its array lands on the truth pixel (< 1e-3 px), and astropy's sky position of the truth pixel is
    # astropy's apparent place (< 0.01 mas, the bound)
    ra0, dec0 = 266.4168, -29.0078
    half_deg = (N + GAP / 2) * 472.1 / 3.6e6
    rng = np.random.default_rng(11)
    n = 400
    dec = dec0 + rng.uniform(-half_deg, half_deg, n)
    ra = ra0 + rng.uniform(-half_deg, half_deg, n) / np.cos(np.radians(dec0))
    pmra, pmdec = rng.normal(-2.0, 3.0, n), rng.normal(-5.6, 2.5, n)
    parallax = 1.0 / rng.uniform(6.0, 10.0, n)
    cat = tmp_path / "stars.csv"
    rows = ["ra,dec,hw,j_h,pmra,pmdec,parallax"] + [
        f"{a:.12f},{d:.12f},14.0,2.0,{p:.6f},{q:.6f},{w:.6f}"
        for a, d, p, q, w in zip(ra, dec, pmra, pmdec, parallax)
    ]
    cat.write_text("\n".join(rows) + "\n")
    path = simulate(
        jsim_bin, tmp_path / "cat", str(cat),
        'observation.start_utc="2032-09-20T03:00:00"', "observation.catalogue_epoch_jyear=2016.0", ORACLE,
    )
    with fits.open(path) as h:
        p = h[0].header
        assert p["APPLACE"] == 1 and p["TIMESYS"] == "UTC" and p["DATE-OBS"].startswith("2032-09-20T03:00")
        app_ra, app_dec = apparent_place_by_astropy(p, ra, dec, pmra, pmdec, parallax)
        # the apparent place is ≈ 20″ of aberration and up to 0.1″ of 16 years' motion from the catalogue's
        moved = np.hypot((app_ra - ra) * np.cos(np.radians(dec)), app_dec - dec) * 3.6e6
        assert moved.min() > 1000.0
        truth = h["TRUTH"].data
        assert len(truth) > 200
        for k in range(1, 5):
            w = array_wcs(h, k)
            mine = truth[truth["array"] == k]
            ids = mine["id"].astype(int)
            pix = w.all_world2pix(
                np.column_stack([app_ra[ids], app_dec[ids]]), 0, tolerance=1e-10, maxiter=100
            )
            err = np.hypot(pix[:, 0] - mine["x"], pix[:, 1] - mine["y"])
            assert err.max() < 1e-3, (k, err.max())
            sky = w.all_pix2world(np.column_stack([mine["x"], mine["y"]]), 0)
            cosd = np.cos(np.radians(sky[:, 1]))
            err_mas = np.hypot((sky[:, 0] - app_ra[ids]) * cosd, sky[:, 1] - app_dec[ids]) * 3.6e6
            assert err_mas.max() < 0.01, (k, err_mas.max())
            # and each such star is on the array's photosensitive pixels by astropy's reckoning too
            b = (N - SMALL["instrument.photosensitive_px"]) / 2
            assert ((pix >= b - 0.5) & (pix < N - b - 0.5)).all()


def test_the_catalogue_place_is_kept_with_the_apparent_place_off(jsim_bin, tmp_path):
    # observation.apparent_place = false: stars land where astropy's WCS puts their catalogue RA/Dec
    ra0, dec0 = 266.4168, -29.0078
    rng = np.random.default_rng(5)
    ra = ra0 + rng.uniform(-0.05, 0.05, 50)
    dec = dec0 + rng.uniform(-0.05, 0.05, 50)
    cat = tmp_path / "stars.csv"
    cat.write_text("ra,dec,pmra\n" + "".join(f"{a:.12f},{d:.12f},5.0\n" for a, d in zip(ra, dec)))
    path = simulate(jsim_bin, tmp_path / "off", str(cat), "observation.apparent_place=false", ORACLE)
    with fits.open(path) as h:
        assert h[0].header["APPLACE"] == 0
        truth = h["TRUTH"].data
        assert len(truth) > 10
        for k in range(1, 5):
            mine = truth[truth["array"] == k]
            if len(mine) == 0:
                continue
            ids = mine["id"].astype(int)
            pix = array_wcs(h, k).all_world2pix(np.column_stack([ra[ids], dec[ids]]), 0, tolerance=1e-10)
            assert np.hypot(pix[:, 0] - mine["x"], pix[:, 1] - mine["y"]).max() < 1e-3


NOMINAL = ["focal_plane.array_offsets_px=[[0.0,0.0],[0.0,0.0],[0.0,0.0],[0.0,0.0]]",
           "focal_plane.array_rotation_errors_deg=[0.0,0.0,0.0,0.0]"]


def test_the_arrays_sit_in_their_places_on_the_sky(jsim_bin, tmp_path):
    # array 1 lower left, 2 lower right, 3 upper left, 4 upper right on a north-up, east-left sky (PA 0);
    # as designed, then as assembled: each array displaced by its offset and turned by its small rotation (the
    # header under the oracle control); without the control the header keeps the design's nominal places
    east = lambda a, b: (a[0] - b[0]) * np.cos(np.radians(b[1])) * 3.6e6 / 472.1  # noqa: E731
    north = lambda a, b: (a[1] - b[1]) * 3.6e6 / 472.1  # noqa: E731
    c = (N - 1) / 2
    centres, pas = {}, {}
    for name, extra in [("nominal", NOMINAL), ("assembled", [ORACLE]), ("design", [])]:
        path = simulate(jsim_bin, tmp_path / name, "bulge", "scene.bulge.density_per_arcmin2=0", *extra)
        with fits.open(path) as h:
            ws = {k: array_wcs(h, k) for k in range(1, 5)}
            centres[name] = {k: ws[k].all_pix2world([[c, c]], 0)[0] for k in range(1, 5)}
            rotation = {k: h[f"ARRAY{k}"].header["ROTATION"] for k in range(1, 5)}
            # each array's +y on the sky: the position angle of its CD matrix's second column
            pas[name] = {k: np.degrees(np.arctan2(ws[k].wcs.cd[0, 1], ws[k].wcs.cd[1, 1])) % 360 for k in ws}
        assert rotation == {1: 0.0, 2: 90.0, 3: 180.0, 4: 270.0}
        if name == "nominal":
            centre = centres[name]
            step = N + GAP  # pixels between neighbouring array centres (the distortion moves them < 1 px)
            assert abs(east(centre[2], centre[1]) + step) < 2.0 and abs(north(centre[2], centre[1])) < 2.0
            assert abs(north(centre[3], centre[1]) - step) < 2.0 and abs(east(centre[3], centre[1])) < 2.0
            assert abs(east(centre[4], centre[3]) + step) < 2.0
    # as assembled: array k's centre moved by its configured offset (focal-plane +x is west at PA 0, so east
    # is −x), its position angle by its rotation error (the distortion moves the centres < 0.1 px more)
    offsets = [[4.2, -7.9], [-6.3, 2.1], [9.4, 5.6], [-1.8, -10.7]]
    errors = [0.06, -0.11, 0.03, -0.08]
    for k in range(1, 5):
        a, b = centres["assembled"][k], centres["nominal"][k]
        assert abs(-east(a, b) - offsets[k - 1][0]) < 0.2 and abs(north(a, b) - offsets[k - 1][1]) < 0.2, k
        turn = (pas["assembled"][k] - pas["nominal"][k] + 180) % 360 - 180
        assert abs(turn - errors[k - 1]) < 1e-6, (k, turn)
        # the design's header: the nominal place and turn, whatever the arrays as assembled
        d = centres["design"][k]
        assert abs(east(d, b)) < 1e-6 and abs(north(d, b)) < 1e-6, k
        assert abs(pas["design"][k] - pas["nominal"][k]) < 1e-9, k
