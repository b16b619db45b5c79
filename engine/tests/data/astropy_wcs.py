"""Make engine/tests/data/astropy_wcs.json: astropy's pixel → sky for the WCS that engine::sky::wcs writes.

    python engine/tests/data/astropy_wcs.py     # needs astropy (the Python tests' venv has it)

The header is built here from the documented convention (engine/src/sky/wcs.rs): CD = s [[-cos ρ, sin ρ],
[sin ρ, cos ρ]], CRPIX = axis + 1, SIP A/B as given; AP/BP are left out (astropy inverts A/B itself).
engine/tests/sky_wcs.rs checks that the engine writes the same keywords and finds the same sky positions.
"""

import json
import math
import pathlib
import warnings

import numpy as np
from astropy.io import fits
from astropy.wcs import WCS

CASES = [
    {"name": "galactic-centre, PA 0, no SIP", "ra": 266.4168, "dec": -29.0078, "pa": 0.0, "rot": 0.0,
     "axis": [983.5, 983.5], "naxis": [1968, 1968], "sip": None},
    {"name": "array of a 2x2 plane, PA 30 + 90, SIP", "ra": 266.4168, "dec": -29.0078, "pa": 30.0,
     "rot": 90.0, "axis": [-20.0, 2010.0], "naxis": [1968, 1968],
     "sip": {"a": [[3, 0, -2.0e-9], [1, 2, -2.0e-9], [2, 0, 1.0e-7]],
             "b": [[0, 3, -2.0e-9], [2, 1, -2.0e-9], [1, 1, -5.0e-8]]}},
    {"name": "near the pole", "ra": 10.0, "dec": 89.5, "pa": -45.0, "rot": 180.0,
     "axis": [100.0, 50.0], "naxis": [200, 100], "sip": None},
]
SCALE_MAS = 472.1
PIXELS = [[0.0, 0.0], [1967.0, 0.0], [0.0, 1967.0], [1967.0, 1967.0], [983.5, 983.5], [250.25, 1710.75]]


def header(c):
    s = SCALE_MAS / 3.6e6
    rho = math.radians(c["pa"] + c["rot"])
    sip = c["sip"] is not None
    h = fits.Header()
    h["NAXIS"] = 2
    h["NAXIS1"], h["NAXIS2"] = c["naxis"]
    h["CTYPE1"] = "RA---TAN-SIP" if sip else "RA---TAN"
    h["CTYPE2"] = "DEC--TAN-SIP" if sip else "DEC--TAN"
    h["CRPIX1"], h["CRPIX2"] = c["axis"][0] + 1.0, c["axis"][1] + 1.0
    h["CRVAL1"], h["CRVAL2"] = c["ra"], c["dec"]
    h["CD1_1"], h["CD1_2"] = -s * math.cos(rho), s * math.sin(rho)
    h["CD2_1"], h["CD2_2"] = s * math.sin(rho), s * math.cos(rho)
    if sip:
        order = max(p + q for p, q, _ in c["sip"]["a"] + c["sip"]["b"])
        h["A_ORDER"] = h["B_ORDER"] = order
        for name in ["a", "b"]:
            for p, q, v in c["sip"][name]:
                h[f"{name.upper()}_{p}_{q}"] = v
    return h


out = []
for c in CASES:
    h = header(c)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # astropy must read the header without a warning
        w = WCS(h)
    pix = np.array([p for p in PIXELS if p[0] < c["naxis"][0] and p[1] < c["naxis"][1]])
    sky = w.all_pix2world(pix, 0)  # origin 0: the engine's 0-based pixels
    out.append({**c, "header": {k: h[k] for k in h if k.startswith(("CRPIX", "CRVAL", "CD"))},
                "pixels": pix.tolist(), "sky": sky.tolist()})
path = pathlib.Path(__file__).with_suffix(".json")
path.write_text(json.dumps(out, indent=1))
print(f"wrote {path}")
