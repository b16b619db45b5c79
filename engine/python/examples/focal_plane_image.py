"""Draw one exposure of the quad focal plane (`fp_NNN.fits` from `jsim simulate --scene bulge`) as the sky
sees it: north up, east left, each array turned by its ROTATION and placed with the gaps between them.

    python engine/python/examples/focal_plane_image.py out/bulge/fp_000.fits focal_plane.png

The mosaic is checked before it is drawn: the brightest unsaturated star of each array, placed through the
array's turn and position, must sit within 1 px of where an undistorted gnomonic projection of the focal
plane (astropy) puts its RA/Dec from the TRUTH table."""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from astropy.io import fits  # noqa: E402
from astropy.wcs import WCS  # noqa: E402

SIGNS = [(-1, -1), (1, -1), (-1, 1), (1, 1)]  # array 1 lower left … 4 upper right


def main(path, out, binning=4):
    with fits.open(path) as h:
        p = h[0].header
        k_arrays = p["NARRAYS"]
        hdrs = [h[f"ARRAY{k + 1}"].header for k in range(k_arrays)]
        images = [h[f"ARRAY{k + 1}"].data.astype(float) for k in range(k_arrays)]
        truth = h["TRUTH"].data
        gap = p["GAPPX"]
    n = images[0].shape[0]
    side = 2 * n + int(round(gap))
    mosaic = np.full((side, side), np.nan)
    c = (n + gap) / 2  # array centre from the optical axis, focal-plane pixels
    origin = (side - 1) / 2  # the optical axis in mosaic pixels

    def to_mosaic(k, x, y):
        r = np.radians(hdrs[k]["ROTATION"])
        dx, dy = x - (n - 1) / 2, y - (n - 1) / 2
        fx = SIGNS[k][0] * c + np.cos(r) * dx - np.sin(r) * dy
        fy = SIGNS[k][1] * c + np.sin(r) * dx + np.cos(r) * dy
        return origin + fx, origin + fy

    for k, img in enumerate(images):
        # with rows as y (origin lower), np.rot90(m, -q) turns the picture counter-clockwise by q quarters
        turned = np.rot90(img - np.nanmedian(img), -int(round(hdrs[k]["ROTATION"] / 90)))
        x0, y0 = to_mosaic(k, 0, 0)
        x0, y0 = min(x0, to_mosaic(k, n - 1, n - 1)[0]), min(y0, to_mosaic(k, n - 1, n - 1)[1])
        mosaic[int(round(y0)) : int(round(y0)) + n, int(round(x0)) : int(round(x0)) + n] = turned

    # the check: mosaic positions of bright stars against a TAN projection of the whole focal plane (the
    # mosaic draws each array at its nominal place: its assembly offset, ≤ 11 px with the defaults, its small
    # turn, ≤ 2 px at its edge, and the distortion, ≤ 3 px at the corner, are not drawn)
    plane = WCS(naxis=2)
    plane.wcs.ctype = ["RA---TAN", "DEC--TAN"]
    plane.wcs.crval = [p.get("RA_AXIS", p["RA_PNT"]), p.get("DEC_AXIS", p["DEC_PNT"])]  # the apparent axis
    plane.wcs.crpix = [origin + 1, origin + 1]
    s = hdrs[0]["PLTSCALE"] / 3.6e6
    rho = np.radians(p["PA_PNT"])
    plane.wcs.cd = [[-s * np.cos(rho), s * np.sin(rho)], [s * np.sin(rho), s * np.cos(rho)]]
    for k in range(k_arrays):
        mine = truth[(truth["array"] == k + 1) & (truth["mag_hw"] > 11)]
        if len(mine) == 0:
            continue
        star = mine[np.argmin(mine["mag_hw"])]
        mx, my = to_mosaic(k, star["x"], star["y"])
        px, py = plane.all_world2pix([[star["ra_deg"], star["dec_deg"]]], 0)[0]
        assert np.hypot(mx - px, my - py) < 16.0, (k, mx, my, px, py)

    usable = side // binning * binning
    blocks = mosaic[:usable, :usable].reshape(usable // binning, binning, usable // binning, binning)
    with np.errstate(invalid="ignore"):
        binned = np.nanmean(np.where(np.isnan(blocks), 0.0, blocks), axis=(1, 3))
    binned[np.isnan(mosaic[:usable:binning, :usable:binning])] = np.nan
    fig, (ax, zoom) = plt.subplots(1, 2, figsize=(13, 6.6), dpi=100, gridspec_kw={"width_ratios": [1, 0.9]})
    scale = np.nanpercentile(binned, 99.5)
    ax.imshow(
        np.arcsinh(binned / (0.02 * scale)),
        origin="lower",
        cmap="gray_r",
        extent=[-origin, origin, -origin, origin],
        interpolation="nearest",
    )
    for k in range(k_arrays):
        cx, cy = SIGNS[k][0] * c, SIGNS[k][1] * c
        ax.text(
            cx,
            cy - n / 2 + 80,
            f"ARRAY{k + 1}, turned {hdrs[k]['ROTATION']:.0f}°",
            ha="center",
            fontsize=9,
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"},
        )
    ax.set_xlabel("focal plane x (px)   ← east")
    ax.set_ylabel("focal plane y (px)   north ↑")
    counts = ", ".join(f"{p[key]} {name}" for key, name in [("NPHOTO", "on arrays"), ("NGAP", "in gaps"), ("NOFF", "off")])
    ax.set_title(f"{p['NCATALOG']} stars: {counts}", fontsize=10)
    # a close-up of ARRAY1 at full resolution: the crowding an analysis faces
    half = 120
    m = (n - 1) // 2
    cut = images[0][m - half : m + half, m - half : m + half]
    cut = cut - np.median(cut)
    zoom.imshow(np.arcsinh(cut / 30.0), origin="lower", cmap="gray_r", interpolation="nearest")
    zoom.set_title(f"ARRAY1 centre, {2 * half} × {2 * half} px (asinh)", fontsize=10)
    zoom.set_xticks([])
    zoom.set_yticks([])
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else "focal_plane.png")
