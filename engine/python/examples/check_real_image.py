"""Check `jsim analyze` on a calibrated file of another observatory with tools that read it on their own.

    python engine/python/examples/check_real_image.py IMAGE OUT [--chip 1] [--photutils PHOTUTILS_CSV]
        [--ext SCI] [--gain G --bias B --flux-min 2e4 --flux-max 3e5 --isolation 8]

IMAGE is the calibrated file (HST `_flt`, JWST `_cal`), OUT the output directory `jsim analyze` wrote for
it; `--ext` names the chip's extension when it is not `SCI` (a ground-based frame's; `GROUP` for a waivered
file's chips, `--chip` the group), with `--gain` and `--bias` as given to jsim. Printed, for the chip:
- the largest distance between jsim's RA/Dec and astropy's `all_pix2world` through the same header (SIP
  included), arcsec;
- jsim's positions of bright (2e4–3e5 e⁻), isolated (no other detection within 8 px), unflagged stars
  against photutils' 2-D Gaussian centroid of a 7 x 7 box (sky = the median of unflagged pixels): the
  median difference and the scatter per axis, px, beside jsim's median Cramér–Rao bound;
- with --photutils, the same stars in photutils' PSF photometry of the chip
  (engine/python/bench/photutils_catalogue.py --ext SCI), matched star by star.
"""

import argparse
import csv
import json
import os

import numpy as np
from astropy.io import fits
from astropy.wcs import WCS


def read_catalogue(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def group_wcs(h, k):
    """The WCS of chip k (1-based) of a waivered file: its row of the group table."""
    row = h[1].data[k - 1]
    w = WCS(naxis=2)
    w.wcs.ctype = [row["CTYPE1"], row["CTYPE2"]]
    w.wcs.crval = [row["CRVAL1"], row["CRVAL2"]]
    w.wcs.crpix = [row["CRPIX1"], row["CRPIX2"]]
    w.wcs.cd = [[row["CD1_1"], row["CD1_2"]], [row["CD2_1"], row["CD2_2"]]]
    return w


def radec_difference_arcsec(image, catalogue, chip=1, ext="SCI"):
    """Largest distance between the catalogue's RA/Dec and astropy's through the chip's header, arcsec."""
    cat = read_catalogue(catalogue)
    with fits.open(image) as h:
        w = group_wcs(h, chip) if ext == "GROUP" else WCS(h[ext, chip].header, h)
    ra, dec = w.all_pix2world(cat["x"], cat["y"], 0)
    d = np.hypot((cat["ra_deg"] - ra) * np.cos(np.radians(dec)), cat["dec_deg"] - dec) * 3600
    return float(d.max())


def centroid_comparison(image, catalogue, plate_scale_mas, chip=1, ext="SCI", gain=1.0, bias=0.0,
                        flux=(2e4, 3e5), isolation=8.0):
    """(n, median difference (x, y), scatter (x, y), median bound) of photutils' centroid less jsim's, px."""
    from photutils.centroids import centroid_2dg

    cat = read_catalogue(catalogue)
    if ext == "GROUP":
        with fits.open(image) as h, fits.open(image.replace("_c0f", "_c1f")) as d:
            sci = (h[0].data[chip - 1].astype(float) - bias) * gain
            dq = d[0].data[chip - 1]
    else:
        with fits.open(image) as h:
            sci = (h[ext, chip].data.astype(float) - bias) * gain
            dq = h["DQ", chip].data if ("DQ", chip) in h else np.zeros(sci.shape, int)
    ny, nx = sci.shape
    x, y, f = cat["x"], cat["y"], cat["flux_e"]
    d = np.hypot(x[:, None] - x[None], y[:, None] - y[None])
    np.fill_diagonal(d, np.inf)
    pick = (d.min(1) > isolation) & (f > flux[0]) & (f < flux[1]) & (cat["flags"] == 0)
    pick &= (x > 8) & (x < nx - 9) & (y > 8) & (y < ny - 9)
    sky = np.median(sci[dq == 0])
    diffs = []
    for xi, yi in zip(x[pick], y[pick]):
        ix, iy = int(round(xi)), int(round(yi))
        box = np.s_[iy - 3 : iy + 4, ix - 3 : ix + 4]
        if (dq[box] != 0).any():
            continue
        cx, cy = centroid_2dg(sci[box] - sky)
        diffs.append((ix - 3 + cx - xi, iy - 3 + cy - yi))
    diffs = np.array(diffs).reshape(-1, 2)
    crlb_px = float(np.median(cat["crlb_x_mas"][pick])) / plate_scale_mas
    return len(diffs), np.median(diffs, axis=0), diffs.std(axis=0), crlb_px


def photutils_comparison(catalogue, photutils_csv, plate_scale_mas, flux=(2e4, 3e5), isolation=8.0):
    """(n, median (x, y), scatter (x, y), median bound) of photutils' PSF fit less jsim's, px, over the bright
    (2e4–3e5 e⁻), isolated (8 px), unflagged stars of both, each matched to the other's nearest within 0.5 px."""
    from scipy.spatial import cKDTree

    cat = read_catalogue(catalogue)
    pu = read_catalogue(photutils_csv)
    x, y, f = cat["x"], cat["y"], cat["flux_e"]
    d = np.hypot(x[:, None] - x[None], y[:, None] - y[None])
    np.fill_diagonal(d, np.inf)
    pick = (d.min(1) > isolation) & (f > flux[0]) & (f < flux[1]) & (cat["flags"] == 0)
    good = pu["flags"] == 0
    tp = cKDTree(np.column_stack([pu["x"][good], pu["y"][good]]))
    dist, j = tp.query(np.column_stack([x[pick], y[pick]]))
    ok = dist < 0.5
    px, py = pu["x"][good][j[ok]], pu["y"][good][j[ok]]
    diffs = np.column_stack([px - x[pick][ok], py - y[pick][ok]])
    crlb_px = float(np.median(cat["crlb_x_mas"][pick][ok])) / plate_scale_mas
    return len(diffs), np.median(diffs, axis=0), diffs.std(axis=0), crlb_px


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("image")
    p.add_argument("out")
    p.add_argument("--chip", type=int, default=1)
    p.add_argument("--photutils", default=None,
                   help="photutils.csv of engine/python/bench/photutils_catalogue.py on the same chip")
    p.add_argument("--ext", default="SCI",
                   help="the chip's extension name (a ground-based frame's); GROUP for a waivered file's chips")
    p.add_argument("--gain", type=float, default=1.0, help="e- per data unit (jsim's --electrons-per-unit)")
    p.add_argument("--bias", type=float, default=0.0, help="data units (jsim's --bias-units)")
    p.add_argument("--flux-min", type=float, default=2e4, help="the stars compared, e-")
    p.add_argument("--flux-max", type=float, default=3e5)
    p.add_argument("--isolation", type=float, default=8.0, help="no other detection within this many px")
    a = p.parse_args()
    flux = (a.flux_min, a.flux_max)
    catalogue = os.path.join(a.out, f"{a.ext.upper()}{a.chip}", "catalogue.csv")
    with open(os.path.join(a.out, "summary.json")) as f:
        scale = json.load(f)["plate_scale_mas"]
    print("RA/Dec against astropy: largest difference "
          f"{radec_difference_arcsec(a.image, catalogue, a.chip, a.ext):.1e} arcsec")
    n, med, std, crlb = centroid_comparison(a.image, catalogue, scale, a.chip, a.ext, a.gain, a.bias, flux,
                                            a.isolation)
    print(
        f"{n} bright isolated stars, photutils centroid_2dg less jsim: median ({med[0]:+.4f}, {med[1]:+.4f}) px, "
        f"scatter ({std[0]:.4f}, {std[1]:.4f}) px; jsim's median bound {crlb:.4f} px"
    )
    if a.photutils:
        n, med, std, crlb = photutils_comparison(catalogue, a.photutils, scale, flux, a.isolation)
        print(
            f"{n} of them in photutils' PSF photometry, photutils less jsim: median ({med[0]:+.4f}, {med[1]:+.4f}) px, "
            f"scatter ({std[0]:.4f}, {std[1]:.4f}) px; jsim's median bound {crlb:.4f} px"
        )


if __name__ == "__main__":
    main()
