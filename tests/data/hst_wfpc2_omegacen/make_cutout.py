"""Make the 4 x 200 x 200 px cutout of a real WFPC2 exposure (four chips) that jsim's tests read.

Source: `stwcs/tests/data/u40x010hm_c0f.fits` and its data-quality companion `u40x010hm_c1f.fits` of the source
distribution of the `stwcs` package, version 1.7.7 (PyPI; STScI, "License :: OSI Approved :: BSD License" in
its PKG-INFO, see README.md here): the WFPC2 exposure u40x010hm of omega Cen (proposal 6941, F555W, 100 s), in
HST's waivered FITS layout: the four chips (PC1, WF2, WF3, WF4) as the planes of one primary cube, each chip's
WCS a row of the ASCII table in extension 1. The cutout keeps pixels x 300-499, y 300-499 (0-based) of every
chip, in both files, with each row's CRPIX (and the primary's, chip 1's) moved so that every chip's WCS still describes the same sky.

    python make_cutout.py path/to/u40x010hm_c0f.fits path/to/u40x010hm_c1f.fits
"""
import sys

from astropy.io import fits

X0, Y0, N = 300, 300, 200


def cut(src: str, dst: str) -> None:
    with fits.open(src) as h:
        header = h[0].header.copy()
        for axis, start in (("1", X0), ("2", Y0)):
            if "CRPIX" + axis in header:
                header["CRPIX" + axis] -= start
        primary = fits.PrimaryHDU(data=h[0].data[:, Y0:Y0 + N, X0:X0 + N], header=header)
        table = h[1].copy()
        table.data["CRPIX1"] -= X0
        table.data["CRPIX2"] -= Y0
        fits.HDUList([primary, table]).writeto(dst, overwrite=True, output_verify="silentfix")


if __name__ == "__main__":
    cut(sys.argv[1], "u40x010hm_cutout_c0f.fits")
    cut(sys.argv[2], "u40x010hm_cutout_c1f.fits")
