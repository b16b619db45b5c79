"""Every FITS file jsim writes against the FITS Standard 4.0 (Pence et al. 2010; the IAU FITS Working Group's
4.0 text, 2018): astropy reads each HDU without a warning and `verify("exception")` passes, and every keyword
the standard reserves (its §4.4, the WCS papers' §8 keywords and the time keywords of Rots et al. 2015) has the
value type the standard gives it, in an HDU where it may appear; the deprecated ones (EPOCH, BLOCKED, CROTAn)
are not written."""

import glob
import os
import re
import subprocess
import warnings

import pytest
from astropy.io import fits

SMALL = [
    "instrument.detector_px=256", "instrument.photosensitive_px=240", "readout.channels=2",
    "readout.channel_width_px=128", "scene.grid_n=4", "scene.grid_spacing_px=50.0", "optics.pupil_samples=64",
    "optics.psf_radius_px=8", "band.wavelength_step_um=0.1", "fidelity.images=1", 'fidelity.backend="cpu"',
    "ace.span_s=60.0",
]

STR, INT, NUM, BOOL = str, int, (int, float), bool
# keyword (n: an index) -> the type the standard gives its value
RESERVED = {
    "SIMPLE": BOOL, "BITPIX": INT, "NAXIS": INT, "NAXISn": INT, "EXTEND": BOOL, "XTENSION": STR, "PCOUNT": INT,
    "GCOUNT": INT, "TFIELDS": INT, "TFORMn": STR, "TTYPEn": STR, "TUNITn": STR, "TBCOLn": INT, "TSCALn": NUM,
    "TZEROn": NUM, "TNULLn": INT, "TDISPn": STR, "TDIMn": STR, "THEAP": INT, "DATE": STR, "ORIGIN": STR,
    "DATE-OBS": STR, "TELESCOP": STR, "INSTRUME": STR, "OBSERVER": STR, "OBJECT": STR, "EQUINOX": NUM,
    "AUTHOR": STR, "REFERENC": STR, "BSCALE": NUM, "BZERO": NUM, "BUNIT": STR, "BLANK": INT, "DATAMAX": NUM,
    "DATAMIN": NUM, "EXTNAME": STR, "EXTVER": INT, "EXTLEVEL": INT, "CTYPEn": STR, "CRPIXn": NUM,
    "CRVALn": NUM, "CDELTn": NUM, "CUNITn": STR, "PCn_n": NUM, "CDn_n": NUM, "PVn_n": NUM, "PSn_n": STR,
    "WCSAXES": INT, "WCSNAME": STR, "CRDERn": NUM, "CSYERn": NUM, "LONPOLE": NUM, "LATPOLE": NUM,
    "RADESYS": STR, "MJD-OBS": NUM, "MJDREF": NUM, "DATEREF": STR, "TIMESYS": STR, "TIMEUNIT": STR,
    "TSTART": NUM, "TSTOP": NUM, "TELAPSE": NUM, "XPOSURE": NUM, "TIMEDEL": NUM, "TIMEPIXR": NUM,
}
DEPRECATED = {"EPOCH", "BLOCKED", "CROTAn"}
ISO_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}(T\d{2}:\d{2}:\d{2}(\.\d+)?)?$")


def generic(key):
    """The reserved name of a keyword: NAXIS2 -> NAXISn, CD1_2 -> CDn_n, TUNIT3 -> TUNITn."""
    k = re.sub(r"(?<=[A-Z])\d+_\d+$", "n_n", key)
    return re.sub(r"(?<=[A-Z])\d+$", "n", k) if k == key else k


def check_hdu(path, i, hdu):
    h = hdu.header
    primary = i == 0
    problems = []
    for key in h.keys():
        if key in ("COMMENT", "HISTORY", ""):
            continue
        g = generic(key)
        if g in DEPRECATED or key in DEPRECATED:
            problems.append(f"{key}: deprecated by the standard")
        want = RESERVED.get(key) or RESERVED.get(g)
        if want is None:
            continue
        v = h[key]
        ok = isinstance(v, want) and not (want is INT and isinstance(v, bool))
        if want == NUM and isinstance(v, bool):
            ok = False
        if not ok:
            problems.append(f"{key} = {v!r}: the standard's type is {want}")
        if key in ("DATE", "DATE-OBS", "DATEREF") and not ISO_DATE.match(str(v)):
            problems.append(f"{key} = {v!r}: not an ISO-8601 date")
    if primary and "XTENSION" in h:
        problems.append("XTENSION in the primary HDU")
    if not primary and "SIMPLE" in h:
        problems.append("SIMPLE in an extension")
    if "BLANK" in h and h.get("BITPIX", 0) < 0:
        problems.append("BLANK in a floating-point HDU")
    if isinstance(hdu, (fits.BinTableHDU, fits.TableHDU)):
        n = h["TFIELDS"]
        for key in h.keys():
            m = re.match(r"^(TTYPE|TFORM|TUNIT|TSCAL|TZERO|TNULL|TDISP|TDIM)(\d+)$", key)
            if m and not 1 <= int(m.group(2)) <= n:
                problems.append(f"{key}: column {m.group(2)} of {n}")
        problems += [f"TUNIT{c}: missing" for c in range(1, n + 1) if f"TUNIT{c}" not in h]
    return [f"{os.path.basename(path)}[{i}] {p}" for p in problems]


@pytest.fixture(scope="module")
def written(jsim_bin, tmp_path_factory):
    """Every kind of FITS file jsim writes: an image and its products, a focal-plane file, an ePSF, a PSF."""
    d = tmp_path_factory.mktemp("fits")
    sets = [a for kv in SMALL for a in ("--set", kv)]
    run = lambda *args: subprocess.run([jsim_bin, *args], cwd=d, check=True, capture_output=True)  # noqa: E731
    run("simulate", "--out", "grid", *sets)
    run("simulate", "--scene", "bulge", "--out", "bulge", *sets)
    run("analyze", "--image", "grid/img_000.fits", "--out", "analysis")
    run("psf", "--out", "psf.fits", *sets)
    files = sorted(glob.glob(str(d / "**" / "*.fits"), recursive=True))
    kinds = {os.path.basename(f).split("_")[0] for f in files}
    assert {"img", "fp", "flat", "psf", "telemetry", "epsf.fits"} <= kinds | {"epsf.fits"}, files
    return files


def test_every_file_reads_in_astropy_without_a_warning_and_verifies(written):
    for f in written:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with fits.open(f) as h:
                h.verify("exception")
                for hdu in h:
                    hdu.header.tostring()
                    _ = hdu.data


def test_reserved_keywords_have_the_standards_types_and_places(written):
    problems = []
    for f in written:
        with fits.open(f) as h:
            for i, hdu in enumerate(h):
                problems += check_hdu(f, i, hdu)
    assert not problems, "\n".join(problems)


def test_the_checker_catches_what_it_should():
    bad = fits.PrimaryHDU()
    bad.header["EPOCH"] = 2000.0
    bad.header["DATE-OBS"] = "25/11/2026"
    bad.header["EXTVER"] = "one"
    found = check_hdu("x.fits", 0, bad)
    assert any("EPOCH" in p for p in found) and any("DATE-OBS" in p for p in found)
    assert any("EXTVER" in p for p in found), found
