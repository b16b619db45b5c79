"""Make the 200 x 200 px cutout of a real HST exposure that jsim's tests read.

Source: `drizzle/tests/data/input1.fits` of the source distribution of the `drizzle` package, version 1.12
(PyPI; BSD-3-Clause, see LICENSE.rst here): the ACS/HRC calibrated exposure j8bt06nyq_flt of 47 Tuc
(NGC 104), F606W, 60 s, with a 4th-order SIP WCS. The cutout keeps the primary header and the SCI, ERR
and DQ extensions of pixels x 800-999, y 650-849 (0-based), with CRPIX moved so that the WCS (and its
SIP polynomials, which are relative to CRPIX) still describes the same sky.

    python make_cutout.py path/to/input1.fits
"""
import sys

from astropy.io import fits

X0, Y0, N = 800, 650, 200


def main(src: str) -> None:
    with fits.open(src) as h:
        out = [fits.PrimaryHDU(header=h[0].header)]
        for name in ("SCI", "ERR", "DQ"):
            ext = h[name, 1]
            hdr = ext.header.copy()
            for axis, start in (("1", X0), ("2", Y0)):
                if "CRPIX" + axis in hdr:
                    hdr["CRPIX" + axis] -= start
            out.append(fits.ImageHDU(data=ext.data[Y0:Y0 + N, X0:X0 + N], header=hdr, name=name))
        fits.HDUList(out).writeto("j8bt06nyq_cutout_flt.fits", overwrite=True)


if __name__ == "__main__":
    main(sys.argv[1])
