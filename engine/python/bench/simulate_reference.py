"""Python against the CLI: simulate the 11 reference frames (the default configuration) both ways.

    python engine/python/bench/simulate_reference.py --jsim target/release/jsim [--backend cpu] [--repeat 2] [--config F]

The CLI runs `jsim simulate --out DIR` (a fresh process: PSFs, ACE series, 11 exposures, FITS + truth CSV +
run.json). Python builds a Session, simulates the 11 exposures and writes each with `write_fits` (the same
image files, no CSVs). Both are timed on the wall clock, best of `--repeat`; the ratio Python / CLI is the
overhead of the module (the issue's bar: ≤ 1.10). A benchmark, not a test: nothing here asserts a time.
"""

import argparse
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

import jsim


def cli_run(jsim_bin, backend, config, out):
    t0 = time.perf_counter()
    subprocess.run(
        [jsim_bin, "simulate", "--backend", backend, "--out", str(out)]
        + (["--config", config] if config else []),
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - t0


def python_run(backend, config, out, write):
    t0 = time.perf_counter()
    cfg = jsim.Config.from_toml(pathlib.Path(config)) if config else jsim.Config.default()
    s = jsim.Session(cfg, backend=backend)
    n = s.config.get("fidelity.images")
    for i in range(n):
        exp = s.simulate(i)
        if write:
            exp.write_fits(out / f"img_{i:03}.fits")
    return time.perf_counter() - t0, exp


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jsim", default="target/release/jsim", help="the jsim binary")
    ap.add_argument("--backend", default="cpu", choices=["cpu", "gpu", "auto"])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--config", default=None, help="a TOML configuration (default: the built-in reference)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        cli, py, py_nowrite = [], [], []
        for r in range(a.repeat):
            cli.append(cli_run(a.jsim, a.backend, a.config, tmp / f"cli{r}"))
            (tmp / f"py{r}").mkdir()
            t, exp = python_run(a.backend, a.config, tmp / f"py{r}", write=True)
            py.append(t)
            py_nowrite.append(python_run(a.backend, a.config, None, write=False)[0])
        # the same frames both ways: the last one
        from astropy.io import fits

        last = sorted((tmp / "cli0").glob("img_*.fits"))[-1]
        with fits.open(last) as h:
            same = np.array_equal(h[0].data, exp.image)
        n = len(list((tmp / "py0").glob("img_*.fits")))
    c, p, q = min(cli), min(py), min(py_nowrite)
    print(f"{n} frames, backend {a.backend}, best of {a.repeat}:")
    print(f"  CLI  jsim simulate (FITS + CSV + run.json)   {c:7.2f} s")
    print(f"  Python simulate + write_fits                 {p:7.2f} s   ratio {p / c:.3f}")
    print(f"  Python simulate only (arrays in memory)      {q:7.2f} s   ratio {q / c:.3f}")
    print(f"  the last image identical both ways: {same}")
    if not same:
        sys.exit("the CLI and Python images differ")


if __name__ == "__main__":
    main()
