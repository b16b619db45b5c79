#!/usr/bin/env python3
"""photutils' crowded-field PSF photometry on any image, as a catalogue `jsim score` reads.

The outside reference of jsim's analysis, on the same footing: the same image, the same calibration flat
product (when given), the same region, and the same scoring step (`jsim score`) for both.

1. reads the image (the primary HDU, or --ext ARRAYk of a focal-plane file with its DQk as a mask), turns ADU
   into electrons (GAIN, BIASADU) and masks non-finite pixels and, without a DQ plane, pixels at SATURATE;
2. divides by the calibration flat product when --flat is given (its primary HDU, or FLATk for ARRAYk);
3. cuts a centred square of --size pixels (0: the whole image);
4. builds an ePSF with EPSFBuilder (oversampling 4, 'quadratic' smoothing, as jsim) from the brightest
   unmasked DAOStarFinder peaks with no other peak within 7 px;
5. runs IterativePSFPhotometry (DAOStarFinder FWHM 2 px at --nsigma x the noise, SourceGrouper 5.5 px: jsim's
   link radius, a 5 x 5 fit shape, a local annulus background, --iters rounds in the residual);
6. writes OUT/photutils.csv (x, y in the image's pixels, flux, flags: photutils' own flags, nonzero = not
   usable), and the truth and jsim catalogues cut to the same region (OUT/truth.csv, OUT/jsim.csv) when given.

  python engine/python/bench/photutils_catalogue.py --image out/outside_20k/image.fits --size 512 \\
      --truth out/outside_20k/truth.csv --jsim out/outside_20k/analysis/catalogue.csv --out out/photutils_20k
  jsim score --catalogue out/photutils_20k/photutils.csv --truth out/photutils_20k/truth.csv \\
      --plate-scale-mas 471.3 --out out/photutils_20k/score_photutils
  jsim score --catalogue out/photutils_20k/jsim.csv --truth out/photutils_20k/truth.csv \\
      --plate-scale-mas 471.3 --out out/photutils_20k/score_jsim
"""

import argparse
import csv
import os
import sys
import time

import numpy as np
from astropy.io import fits
from astropy.nddata import NDData
from astropy.stats import sigma_clipped_stats
from astropy.table import Table
import photutils
from photutils.background import LocalBackground, MMMBackground
from photutils.detection import DAOStarFinder
from photutils.psf import EPSFBuilder, IterativePSFPhotometry, SourceGrouper, extract_stars

photutils.future_column_names = True  # x_centroid, not the deprecated xcentroid


def gain_of(h, hdr):
    """e- per data unit: GAIN (jsim), else 1 for a calibrated chip in ELECTRONS, else ATODGAIN for COUNTS."""
    if "GAIN" in hdr:
        return hdr["GAIN"]
    unit = hdr.get("BUNIT", "").strip().upper()
    if unit.startswith("ELECTRON"):
        return 1.0
    if unit.startswith("COUNT") and "ATODGAIN" in h[0].header:
        return h[0].header["ATODGAIN"]
    sys.exit(f"no GAIN, and BUNIT {unit!r} is not ELECTRONS or COUNTS with ATODGAIN")


def load(path, ext, flat, flat_ext, gain=None, bias=None, saturate=None, group=None):
    """The image in electrons, its mask and plate scale; gain (e- per data unit), bias and saturation (data
    units) as given, else from the header (a raw frame's, as jsim's --electrons-per-unit, --bias-units and
    --saturate-units). `group` k: the k-th plane (1-based) of a waivered file's primary cube (WFPC2's
    `_c0f`), its DQ the companion `_c1f`'s plane."""
    if group is not None:
        with fits.open(path) as h, fits.open(path.replace("_c0f", "_c1f")) as d:
            raw = h[0].data[group - 1].astype(float)
            e = (raw - (bias or 0.0)) * (gain if gain is not None else h[0].header["ATODGAIN"])
            bad = ~np.isfinite(e) | (d[0].data[group - 1] != 0)
            row = h[1].data[group - 1]
            scale = float(np.sqrt(abs(row["CD1_1"] * row["CD2_2"] - row["CD1_2"] * row["CD2_1"])) * 3.6e6)
        e[bad] = 0.0
        return e, bad, scale
    with fits.open(path) as h:
        hdu = h[int(ext) if ext and ext.isdigit() else ext] if ext else h[0]
        hdr = hdu.header
        raw = hdu.data.astype(float)
        b = bias if bias is not None else hdr.get("BIASADU", 0.0)
        e = (raw - b) * (gain if gain is not None else gain_of(h, hdr))
        bad = ~np.isfinite(e)
        if saturate is not None:
            bad |= raw >= saturate
        # a focal plane's ARRAYk has DQk; a calibrated file's SCI chip (HST, JWST) its DQ
        dq_name = "DQ" + ext[len("ARRAY"):] if ext and ext.startswith("ARRAY") else "DQ"
        if dq_name in h:
            bad |= h[dq_name].data != 0
        elif "SATURATE" in hdr:
            bad |= hdu.data >= hdr["SATURATE"]
        scale = hdr.get("PLTSCALE", np.nan)
        if not np.isfinite(scale) and "CD1_1" in hdr:
            scale = float(np.sqrt(abs(hdr["CD1_1"] * hdr["CD2_2"] - hdr.get("CD1_2", 0.0) * hdr.get("CD2_1", 0.0))) * 3.6e6)
    if flat:
        with fits.open(flat) as f:
            e = e / f[flat_ext or 0].data
    e[bad] = 0.0
    return e, bad, scale


def cut_csv(src, dst, lo, hi, extra=None):
    """Rows of a CSV with lo <= x, y < hi (and extra(row) true), header kept."""
    with open(src) as f, open(dst, "w", newline="") as g:
        r = csv.DictReader(f)
        w = csv.DictWriter(g, fieldnames=r.fieldnames)
        w.writeheader()
        for row in r:
            x, y = float(row["x"]), float(row["y"])
            if lo <= x < hi and lo <= y < hi and (extra is None or extra(row)):
                w.writerow(row)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--image", required=True)
    ap.add_argument("--ext", default=None,
                    help="ARRAYk of a focal-plane file, sci (SCI) of a calibrated HST/JWST file, or an extension's "
                         "number (default: the primary HDU)")
    ap.add_argument("--gain", type=float, default=None, help="e- per data unit (default: the header's)")
    ap.add_argument("--bias", type=float, default=None, help="a raw frame's bias, data units")
    ap.add_argument("--saturate", type=float, default=None, help="a raw frame's saturation level, data units")
    ap.add_argument("--group", type=int, default=None,
                    help="the k-th chip (1-based) of a waivered file's primary cube (WFPC2's _c0f; DQ from _c1f)")
    ap.add_argument("--flat", default=None, help="the calibration flat product (flat_cal.fits)")
    ap.add_argument("--size", type=int, default=512, help="centred cut, px (0: the whole image)")
    ap.add_argument("--nsigma", type=float, default=5.0)
    ap.add_argument("--iters", type=int, default=2)
    ap.add_argument("--truth", default=None, help="truth CSV (x, y, mag) to cut to the region")
    ap.add_argument("--jsim", default=None, help="jsim's catalogue.csv to cut to the region")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    a.ext = a.ext.upper() if a.ext else None  # extension names are read without regard to case

    flat_ext = "FLAT" + a.ext[len("ARRAY"):] if a.ext and a.ext.startswith("ARRAY") else None
    e, bad, scale = load(a.image, a.ext, a.flat, flat_ext, a.gain, a.bias, a.saturate, a.group)
    n = e.shape[0]
    size = n if a.size <= 0 else min(a.size, n)
    x0 = (n - size) // 2
    cut = (slice(x0, x0 + size), slice(x0, x0 + size))
    data, mask = e[cut], bad[cut]

    t_start = time.perf_counter()
    _, med, std = sigma_clipped_stats(data[~mask], sigma=3.0)
    img = data - med
    finder = DAOStarFinder(threshold=a.nsigma * std, fwhm=2.0)
    peaks = finder(img, mask=mask)
    px, py, pf = (np.asarray(peaks[c]) for c in ("x_centroid", "y_centroid", "flux"))
    from scipy.spatial import cKDTree

    tree = cKDTree(np.column_stack([px, py]))
    nn = np.array([len(tree.query_ball_point((x, y), 7.0)) for x, y in zip(px, py)])
    edge = (px > 13) & (px < size - 13) & (py > 13) & (py < size - 13)
    clean = np.array(
        [not mask[int(y) - 6 : int(y) + 7, int(x) - 6 : int(x) + 7].any() if ok else False for x, y, ok in zip(px, py, edge)]
    )
    pick = np.where((nn == 1) & edge & clean)[0]
    star_img = img
    if len(pick) < 10:
        # a detector whose flagged pixels leave few clean boxes (STIS's): stars with a clean core (no flagged
        # pixel within 2 px), as jsim loosens its own choice; their flagged wing pixels interpolated from
        # their neighbours (photutils' ePSF fit takes no NaN)
        from astropy.convolution import Gaussian2DKernel, interpolate_replace_nans

        core = np.array(
            [not mask[int(y) - 2 : int(y) + 3, int(x) - 2 : int(x) + 3].any() if ok else False
             for x, y, ok in zip(px, py, edge)]
        )
        pick = np.where((nn == 1) & edge & core)[0]
        star_img = interpolate_replace_nans(np.where(mask, np.nan, img), Gaussian2DKernel(1.0))
        star_img = np.nan_to_num(star_img)
        print(f"photutils: {len(pick)} ePSF stars with a clean core (too few clean boxes)")
    pick = pick[np.argsort(-pf[pick])][:200]
    stars = extract_stars(NDData(star_img), Table({"x": px[pick], "y": py[pick]}), size=25)
    epsf = EPSFBuilder(oversampling=4, smoothing_kernel="quadratic", maxiters=10, progress_bar=False)(stars)
    epsf = getattr(epsf, "epsf", epsf[0] if isinstance(epsf, tuple) else epsf)
    phot = IterativePSFPhotometry(
        epsf,
        (5, 5),
        finder,
        grouper=SourceGrouper(min_separation=5.5),
        aperture_radius=3,
        maxiters=a.iters,
        mode="new",
        local_bkg_estimator=LocalBackground(7, 10, bkg_estimator=MMMBackground()),
    )
    res = phot(img, mask=mask)
    seconds = time.perf_counter() - t_start

    os.makedirs(a.out, exist_ok=True)
    fx, fy = np.asarray(res["x_fit"]) + x0, np.asarray(res["y_fit"]) + x0
    ff = np.asarray(res["flux_fit"])
    flags = np.asarray(res["flags"]) if "flags" in res.colnames else np.zeros(len(res), int)
    ok = np.isfinite(fx) & np.isfinite(fy)
    with open(os.path.join(a.out, "photutils.csv"), "w") as f:
        f.write("x,y,flux_e,flags\n")
        for x, y, fl, g in zip(fx[ok], fy[ok], ff[ok], flags[ok]):
            # photutils' flags, nonzero = a fit it does not vouch for; jsim score reads bit 1 (`not converged`)
            f.write(f"{x:.6f},{y:.6f},{fl:.3f},{1 if g else 0}\n")
    lo, hi = x0 - 0.5, x0 + size - 0.5
    if a.truth:
        cut_csv(a.truth, os.path.join(a.out, "truth.csv"), lo, hi)
    if a.jsim:
        cut_csv(a.jsim, os.path.join(a.out, "jsim.csv"), lo, hi)
    print(f"photutils: {int(ok.sum())} stars in {seconds:.1f} s on {size}x{size} px from ({x0}, {x0}); "
          f"plate scale {scale} mas/px; wrote {a.out}/photutils.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
