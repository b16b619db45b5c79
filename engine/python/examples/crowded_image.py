#!/usr/bin/env python3
"""A crowded single-array image made without jsim: the outside input of `jsim analyze` and `jsim score`.

It stands for an image from another simulator or a detector test, written with numpy and astropy alone:

* stars at uniform random positions over the array, magnitudes drawn from an exponential luminosity
  function dN/dm ∝ 10^(0.3 m) between --mag-min and --mag-max (the slope of bulge counts in the near
  infrared, roughly; a choice of this script, not a fit);
* fluxes through jsim's documented zero point (5.8e8 e-/s at Hw 0) and a 12.5-s exposure;
* a pixel-integrated circular Gaussian PSF of σ = --sigma-px (0.75 px: FWHM 1.77 px ≈ the optical PSF's
  735 mas at 471 mas/px, slightly broadened) — deliberately *not* jsim's optics, so the analysis has to
  build its ePSF from the image;
* a flat sky of --sky-e electrons, Poisson noise, Gaussian read noise of the CDS image (√2 × 15 e-),
  gain 3 e-/ADU, a bias of 1000 ADU, clipping at the full well (150 000 e-) and at 16 bits;
* the usual headers: GAIN, RDNOISE, BIASADU, EXPTIME, SATURATE, PLTSCALE, BUNIT (no DQ plane, no jsim
  extension).

Pixels are numbered from 0 and an integer coordinate is a pixel centre (jsim's convention: pixel (X, Y)
covers X - 1/2 <= x < X + 1/2), written in the truth file `truth.csv` as x, y, mag.

  python engine/python/examples/crowded_image.py --stars 20000 --out out/outside_20k
  jsim analyze --image out/outside_20k/image.fits --out out/outside_20k/analysis
  jsim score --catalogue out/outside_20k/analysis/catalogue.csv --truth out/outside_20k/truth.csv \
      --out out/outside_20k/score
"""

import argparse
import math
import os
import sys

import numpy as np
from astropy.io import fits

ZERO_POINT_E_PER_S = 5.8e8
EXPTIME_S = 12.5
GAIN_E_PER_ADU = 3.0
READ_NOISE_E = math.sqrt(2.0) * 15.0
BIAS_ADU = 1000.0
FULL_WELL_E = 150000.0
PLATE_SCALE_MAS = 471.3
HALF_STAMP_PX = 6


def erf(x):
    """Vectorised error function (numpy has none; math.erf per element)."""
    return np.vectorize(math.erf, otypes=[float])(x)


def draw_magnitudes(rng, n, lo, hi, slope=0.3):
    """Inverse-CDF draws from dN/dm ∝ 10^(slope m) on [lo, hi]."""
    a = 10.0 ** (slope * lo)
    b = 10.0 ** (slope * hi)
    return np.log10(a + rng.random(n) * (b - a)) / slope


def render(size, x, y, flux, sigma_px):
    """Sum of pixel-integrated Gaussians: each star's flux over its (2h+1)^2 stamp, exact per pixel."""
    img = np.zeros((size, size))
    h = HALF_STAMP_PX
    offsets = np.arange(-h, h + 1)
    cx = np.rint(x).astype(int)
    cy = np.rint(y).astype(int)
    s = sigma_px * math.sqrt(2.0)
    # fraction of a star's light in pixel column cx+o: Φ((cx+o+½−x)/σ) − Φ((cx+o−½−x)/σ)
    edges_x = (cx[:, None] + offsets[None, :] - x[:, None])
    edges_y = (cy[:, None] + offsets[None, :] - y[:, None])
    fx = 0.5 * (erf((edges_x + 0.5) / s) - erf((edges_x - 0.5) / s))
    fy = 0.5 * (erf((edges_y + 0.5) / s) - erf((edges_y - 0.5) / s))
    stamp = flux[:, None, None] * fy[:, :, None] * fx[:, None, :]
    px = cx[:, None, None] + offsets[None, None, :]
    py = cy[:, None, None] + offsets[None, :, None]
    px = np.broadcast_to(px, stamp.shape)
    py = np.broadcast_to(py, stamp.shape)
    inside = (px >= 0) & (px < size) & (py >= 0) & (py < size)
    np.add.at(img, (py[inside], px[inside]), stamp[inside])
    return img


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--stars", type=int, default=20000, help="stars on the array (default 20000)")
    p.add_argument("--size", type=int, default=1968, help="array side in pixels (default 1968)")
    p.add_argument("--mag-min", type=float, default=10.0)
    p.add_argument("--mag-max", type=float, default=17.5)
    p.add_argument("--sigma-px", type=float, default=0.75, help="Gaussian PSF sigma in pixels")
    p.add_argument("--sky-e", type=float, default=100.0, help="sky + dark per pixel per exposure [e-]")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", required=True, help="output directory (image.fits, truth.csv)")
    a = p.parse_args(argv)
    for name, v, lo in [("--stars", a.stars, 0), ("--size", a.size, 16)]:
        if v < lo:
            sys.exit(f"{name} {v}: must be >= {lo}")
    if not (0.2 <= a.sigma_px <= 5.0):
        sys.exit(f"--sigma-px {a.sigma_px}: allowed [0.2, 5]")
    if not a.mag_min < a.mag_max:
        sys.exit("--mag-min must be < --mag-max")

    rng = np.random.default_rng(a.seed)
    x = rng.uniform(-0.5, a.size - 0.5, a.stars)
    y = rng.uniform(-0.5, a.size - 0.5, a.stars)
    mag = draw_magnitudes(rng, a.stars, a.mag_min, a.mag_max)
    flux = ZERO_POINT_E_PER_S * 10.0 ** (-0.4 * mag) * EXPTIME_S

    expected = render(a.size, x, y, flux, a.sigma_px) + a.sky_e
    electrons = rng.poisson(expected).astype(float)
    electrons = np.minimum(electrons, FULL_WELL_E)
    electrons += rng.normal(0.0, READ_NOISE_E, electrons.shape)
    adu = np.clip(np.round(electrons / GAIN_E_PER_ADU + BIAS_ADU), 0, 65535).astype(np.float32)

    os.makedirs(a.out, exist_ok=True)
    hdr = fits.Header()
    hdr["GAIN"] = (GAIN_E_PER_ADU, "[e-/ADU]")
    hdr["RDNOISE"] = (READ_NOISE_E, "[e-] read noise of the image")
    hdr["BIASADU"] = (BIAS_ADU, "[ADU] bias")
    hdr["EXPTIME"] = (EXPTIME_S, "[s] exposure")
    hdr["SATURATE"] = (min(FULL_WELL_E / GAIN_E_PER_ADU + BIAS_ADU, 65535.0) - 1.0, "[ADU] saturation")
    hdr["PLTSCALE"] = (PLATE_SCALE_MAS, "[mas/pix] plate scale")
    hdr["BUNIT"] = "adu"
    hdr["ORIGIN"] = "crowded_image.py (numpy, not jsim)"
    hdr["NSTARS"] = (a.stars, "stars drawn")
    hdr["PSFSIGMA"] = (a.sigma_px, "[pix] Gaussian PSF sigma")
    hdr["SEED"] = (a.seed, "numpy default_rng seed")
    fits.PrimaryHDU(adu, header=hdr).writeto(os.path.join(a.out, "image.fits"), overwrite=True)
    with open(os.path.join(a.out, "truth.csv"), "w") as f:
        f.write("x,y,mag\n")
        for xi, yi, mi in zip(x, y, mag):
            f.write(f"{xi:.6f},{yi:.6f},{mi:.4f}\n")
    print(f"wrote {a.out}/image.fits ({a.size}x{a.size}, {a.stars} stars) and truth.csv")


if __name__ == "__main__":
    main()
