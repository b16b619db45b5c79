"""Make the 256 x 256 px cutout of a real HST CR-split pair that jsim's tests read.

Source: `stwcs/tests/data/o4k19a010_flt.fits` of the source distribution of the `stwcs` package, version
1.7.7 (PyPI; STScI, "License :: OSI Approved :: BSD License" in its PKG-INFO, see README.md here): the
STIS/CCD exposure o4k19a010 of a field in M33's disk (proposal 7908, 50CCD, unfiltered), a CR-split pair of
150 s exposures in one file (SCI,1 and SCI,2 with their ERR and DQ, the same pointing 194 s apart). The
cutout keeps the primary header and every SCI, ERR and DQ extension over pixels x 702-957, y 168-423
(0-based), with CRPIX moved so that each WCS still describes the same sky.

    python make_cutout.py path/to/o4k19a010_flt.fits
"""
import sys

from astropy.io import fits

X0, Y0, N = 702, 168, 256


def main(src: str) -> None:
    with fits.open(src) as h:
        out = [fits.PrimaryHDU(header=h[0].header)]
        for ext in h[1:]:
            if ext.name not in ("SCI", "ERR", "DQ") or ext.data is None or ext.data.ndim != 2:
                continue
            hdr = ext.header.copy()
            for axis, start in (("1", X0), ("2", Y0)):
                if "CRPIX" + axis in hdr:
                    hdr["CRPIX" + axis] -= start
            out.append(fits.ImageHDU(data=ext.data[Y0:Y0 + N, X0:X0 + N], header=hdr, name=ext.name,
                                     ver=ext.ver))
        fits.HDUList(out).writeto("o4k19a010_cutout_flt.fits", overwrite=True)


if __name__ == "__main__":
    main(sys.argv[1])
