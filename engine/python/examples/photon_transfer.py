"""The gain and read noise of a raw camera from two frames of one field: a photon-transfer fit on their sky.

    python engine/python/examples/photon_transfer.py FRAME1 FRAME2 --bias 2048

For a raw frame whose header states neither gain nor read noise (a DSLR's, a ground-based CCD's), before
`jsim analyze --electrons-per-unit G --read-noise-e R --bias-units B`. The two frames are differenced, so the
flat field and the stars that stay put cancel; the variance of the difference over two, in data units², is

    var = level / G + (R / G)²

for the sky level (data units, bias removed) of each 2 × 2 phase of the pixel grid: the four colours of a Bayer
mosaic see the sky at four levels, which is what separates G from R. The variance is the median absolute
deviation's (× 1.4826)², so the stars that moved between the frames weigh little. Printed: each phase's level and
variance, and the fitted G (e⁻ per data unit) and R (e⁻). With the phases at one level (a monochrome camera) the
fit cannot separate them, and says so.
"""

import argparse

import numpy as np
from astropy.io import fits


def first_image(path):
    with fits.open(path) as h:
        for hdu in h:
            if hdu.data is not None and hdu.data.ndim == 2:
                return hdu.data.astype(float)
    raise SystemExit(f"{path}: no 2-D image")


def robust_variance(x):
    x = x[np.isfinite(x)]
    return (1.4826 * np.median(np.abs(x - np.median(x)))) ** 2


def photon_transfer(a, b, bias):
    """[(level, variance)] per 2 × 2 phase, and (gain, read noise) of the straight-line fit (None if the
    levels span less than 10 %)."""
    points = []
    for i in (0, 1):
        for j in (0, 1):
            pa, pb = a[i::2, j::2] - bias, b[i::2, j::2] - bias
            points.append((float(np.median(pa)), robust_variance(pa - pb) / 2))
    p = np.array(points)
    if p[:, 0].max() < 1.1 * p[:, 0].min():
        return points, None
    slope, intercept = np.polyfit(p[:, 0], p[:, 1], 1)
    gain = 1 / slope
    return points, (gain, float(np.sqrt(max(intercept, 0.0))) * gain)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frame1")
    ap.add_argument("frame2")
    ap.add_argument("--bias", type=float, default=0.0, help="the raw frames' bias, data units")
    a = ap.parse_args()
    points, fit = photon_transfer(first_image(a.frame1), first_image(a.frame2), a.bias)
    for k, (level, var) in enumerate(points):
        print(f"phase ({k // 2}, {k % 2}): sky {level:.1f}, variance of the difference / 2 {var:.1f} (data units)")
    if fit is None:
        print("the phases see one sky level: gain and read noise cannot be told apart")
    else:
        print(f"gain {fit[0]:.2f} e- per data unit, read noise {fit[1]:.1f} e-")


if __name__ == "__main__":
    main()
