#!/usr/bin/env python3
"""The outside reference for `jsim crowded` (issue #16): photutils' IterativePSFPhotometry on the same array.

Run `jsim crowded --aces gaussian --save-images --out out/crowded` first; this script then

1. reads ARRAY<k>, DQ<k> and the TRUTH rows of array k from out/crowded/gaussian/fp_000.fits, turns ADU into
   electrons (GAIN, BIASADU) and masks every pixel with a DQ bit (border, saturated, ADC clipped);
2. cuts a centred square of --size pixels (0: the whole array);
3. builds an ePSF with photutils' EPSFBuilder (oversampling 4 and the 'quadratic' smoothing kernel, as jsim;
   photutils' default 'quartic' measured 15 mas instead of 6.5 mas on the Hw 12-14 isolated stars of a sparse
   field) from the brightest unsaturated stars without a neighbour within 7 px (DAOStarFinder peaks);
4. runs IterativePSFPhotometry: DAOStarFinder (FWHM 2 px, threshold --nsigma x the background noise),
   SourceGrouper (min_separation 5.5 px: jsim's link radius), fit_shape 5 x 5, a local annulus background,
   --iters iterations of finding in the residual;
5. matches both catalogues to the truth (nearest within 1 px after the median offset) and prints, per bin of
   true Hw, completeness and the std of fitted - true (mas, per axis combined as sqrt((sx^2 + sy^2)/2),
   each catalogue's median offset removed) for photutils and for jsim (out/crowded/stars_gaussian.csv, the
   same array and region), and both times.

The run stops at --timeout-s (SIGALRM) and reports how far it got. photutils does not flat-field: the image
is taken as the detector wrote it; jsim divides by its calibration flat (0.2 % error), which matters little
against the 1 % inter-pixel flat at these signal levels.

  python engine/python/bench/crowded_photutils.py --fits out/crowded/gaussian/fp_000.fits \
      --stars out/crowded/stars_gaussian.csv --array 1 --size 512
"""

import argparse
import signal
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


class Timeout(Exception):
    pass


def alarm(_sig, _frame):
    raise Timeout()


def load(path, k):
    with fits.open(path) as h:
        img = h[f"ARRAY{k}"]
        hdr = img.header
        e = (img.data.astype(float) - hdr.get("BIASADU", 0.0)) * hdr["GAIN"]
        bad = h[f"DQ{k}"].data != 0
        t = Table(h["TRUTH"].data)
        t = t[t["array"] == k]
        return e, bad, t, hdr["PLTSCALE"]


def match(x, y, tx, ty, radius=1.0):
    """Index of the nearest truth star within `radius` px of each position (after the median offset), -1 if none."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.column_stack([tx, ty]))
    d, j = tree.query(np.column_stack([x, y]), distance_upper_bound=20.0)
    ok = np.isfinite(d)
    off = (np.median(x[ok] - tx[j[ok]]), np.median(y[ok] - ty[j[ok]])) if ok.sum() >= 3 else (0.0, 0.0)
    d, j = tree.query(np.column_stack([x - off[0], y - off[1]]), distance_upper_bound=radius)
    j[~np.isfinite(d)] = -1
    # one-to-one: the closest claim wins
    order = np.argsort(d)
    taken = set()
    for i in order:
        if j[i] >= 0 and j[i] in taken:
            j[i] = -1
        elif j[i] >= 0:
            taken.add(j[i])
    return j


def binned(hw, dx, dy, edges):
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        s = (hw >= lo) & (hw < hi)
        n = int(s.sum())
        acc = np.sqrt((np.std(dx[s]) ** 2 + np.std(dy[s]) ** 2) / 2) if n >= 3 else np.nan
        rows.append((n, acc))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fits", default="out/crowded/gaussian/fp_000.fits")
    ap.add_argument("--stars", default="out/crowded/stars_gaussian.csv")
    ap.add_argument("--array", type=int, default=1)
    ap.add_argument("--size", type=int, default=512, help="centred cut, px (0: the whole array)")
    ap.add_argument("--nsigma", type=float, default=5.0)
    ap.add_argument("--iters", type=int, default=2)
    ap.add_argument("--timeout-s", type=float, default=1800.0)
    a = ap.parse_args()

    e, bad, truth, scale = load(a.fits, a.array)
    n = e.shape[0]
    size = n if a.size <= 0 else min(a.size, n)
    x0 = (n - size) // 2
    cut = (slice(x0, x0 + size), slice(x0, x0 + size))
    data, mask = e[cut], bad[cut]
    inside = (truth["x"] >= x0) & (truth["x"] < x0 + size) & (truth["y"] >= x0) & (truth["y"] < x0 + size)
    t = truth[inside]
    tx, ty, thw = np.asarray(t["x"]) - x0, np.asarray(t["y"]) - x0, np.asarray(t["mag_hw"])
    print(f"array {a.array}: {size}x{size} px from ({x0}, {x0}); {len(t)} truth stars in the cut")

    signal.signal(signal.SIGALRM, alarm)
    signal.alarm(int(a.timeout_s))
    stage = "background"
    t_start = time.perf_counter()
    try:
        _, med, std = sigma_clipped_stats(data[~mask], sigma=3.0)
        img = data - med
        stage = "ePSF"
        t0 = time.perf_counter()
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
        pick = pick[np.argsort(-pf[pick])][:200]
        stars = extract_stars(NDData(img), Table({"x": px[pick], "y": py[pick]}), size=25)
        try:
            epsf = EPSFBuilder(oversampling=4, smoothing_kernel="quadratic", maxiters=10, progress_bar=False)(stars)
        except ValueError as e:
            # photutils 3's EPSFBuilder refuses an ePSF with oversampled cells no star sampled (too few stars)
            raise SystemExit(f"--size {size}: photutils built no ePSF from {len(pick)} isolated stars ({e}); cut a larger square") from None
        epsf = getattr(epsf, "epsf", epsf[0] if isinstance(epsf, tuple) else epsf)
        t_epsf = time.perf_counter() - t0
        print(f"ePSF from {len(pick)} stars in {t_epsf:.1f} s")
        stage = "IterativePSFPhotometry"
        t0 = time.perf_counter()
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
        t_fit = time.perf_counter() - t0
    except Timeout:
        print(f"photutils did not finish: stopped in the {stage} stage after {time.perf_counter() - t_start:.0f} s "
              f"(--timeout-s {a.timeout_s:.0f})")
        return 2
    finally:
        signal.alarm(0)
    total = time.perf_counter() - t_start
    print(f"photutils: {len(res)} stars in {t_fit:.1f} s of photometry, {total:.1f} s in all")

    edges = np.arange(np.floor(thw.min()), np.ceil(thw.max()) + 0.5, 1.0) if len(thw) else np.array([0, 1])
    fx, fy = np.asarray(res["x_fit"]), np.asarray(res["y_fit"])
    good = np.isfinite(fx) & np.isfinite(fy)
    if "flags" in res.colnames:
        good &= np.asarray(res["flags"]) == 0
    j = match(fx[good], fy[good], tx, ty)
    m = j >= 0
    pdx = (fx[good][m] - tx[j[m]]) * scale
    pdy = (fy[good][m] - ty[j[m]]) * scale
    pdx, pdy = pdx - np.median(pdx), pdy - np.median(pdy)
    p_rows = binned(thw[j[m]], pdx, pdy, edges)

    js = Table.read(a.stars, format="ascii.csv")
    js = js[(js["array"] == a.array) & (js["x_px"] >= x0) & (js["x_px"] < x0 + size) & (js["y_px"] >= x0) & (js["y_px"] < x0 + size)]
    REJECT = 1 | 8 | 16 | 32 | 64 | 128  # analysis::epsf::fit::flags::REJECT
    ok = (np.asarray(js["flags"]) & REJECT) == 0
    jj = match(np.asarray(js["x_px"])[ok] - x0, np.asarray(js["y_px"])[ok] - x0, tx, ty)
    mm = jj >= 0
    jdx = (np.asarray(js["x_px"])[ok][mm] - x0 - tx[jj[mm]]) * scale
    jdy = (np.asarray(js["y_px"])[ok][mm] - x0 - ty[jj[mm]]) * scale
    jdx, jdy = jdx - np.median(jdx), jdy - np.median(jdy)
    j_rows = binned(thw[jj[mm]], jdx, jdy, edges)

    print(f"\n| Hw | truth | photutils found | photutils [mas] | jsim found | jsim [mas] |")
    print("|---|---|---|---|---|---|")
    for (lo, hi), (pn, pa), (jn, ja) in zip(zip(edges[:-1], edges[1:]), p_rows, j_rows):
        nt = int(((thw >= lo) & (thw < hi)).sum())
        if nt == 0:
            continue
        print(f"| {lo:.0f}-{hi:.0f} | {nt} | {pn} | {pa:.2f} | {jn} | {ja:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
