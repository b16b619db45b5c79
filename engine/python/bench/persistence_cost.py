"""Persistence's astrometric cost along a sequence.

Run the same sequence twice, noise-free (so that the only difference is the persistence), with persistence off
and on, then compare each star's measured position between the two runs (the scoring's truth files):

    jsim sequence --spec seq.toml --countermeasure none --set ace.case='"gaussian"' \
        --set detector.shot_noise=false --set detector.read_noise=false --out off
    jsim sequence ... (the same) --set detector.persistence.enabled=true --out on
    python persistence_cost.py off on

Prints, per exposure, the stars matched in both runs, the shift of their positions (on - off, mas): its
99th percentile and largest value, the fraction of stars moved by more than 0.4 mas (a tenth of the 4-mas
budget), the same for Hw 12-14 with their accuracy against the truth in each run (rms per axis, 5-sigma clipped), and the
unmatched detections of each run (ghosts taken for stars). Run with noise, the accuracies say what persistence
costs a noisy exposure.
"""

import csv
import sys
from pathlib import Path

import numpy as np


def load(path: Path) -> tuple[dict, int]:
    rows, unmatched = {}, 0
    with open(path) as f:
        for r in csv.DictReader(f):
            tid = int(r["truth_id"])
            if tid < 0:
                unmatched += 1
                continue
            rows[(int(r["array"]), tid)] = (float(r["dx_mas"]), float(r["dy_mas"]))
    return rows, unmatched


def summary(s: np.ndarray) -> str:
    if len(s) == 0:
        return "none"
    return (
        f"{len(s)} stars, p99 {np.percentile(s, 99):.3f} mas, max {s.max():.2f} mas, "
        f"> 0.4 mas: {np.mean(s > 0.4) * 100:.2f} %"
    )


def accuracy(rows: dict, keys: list) -> float:
    """rms position error (mas per axis) against the truth, 5-sigma clipped around a MAD scale."""
    d = np.array([rows[k] for k in keys]).ravel()
    if len(d) == 0:
        return float("nan")
    scale = 1.4826 * np.median(np.abs(d - np.median(d)))
    d = d[np.abs(d) < 5 * scale]
    return float(np.sqrt(np.mean(d**2)))


def main() -> None:
    off, on = Path(sys.argv[1]), Path(sys.argv[2])
    with open(off / "field.csv") as f:
        hw = np.array([float(r["hw"]) for r in csv.DictReader(f)])
    for path in sorted((off / "exposures").glob("*_truth.csv")):
        a, ua = load(path)
        b, ub = load(on / "exposures" / path.name)
        keys = [k for k in a if k in b]
        shift = np.array([np.hypot(b[k][0] - a[k][0], b[k][1] - a[k][1]) for k in keys])
        mags = np.array([hw[k[1]] for k in keys])
        bright = (mags >= 12) & (mags < 14)
        e = path.name.split("_")[0]
        print(f"exposure {e}: all {summary(shift)}; unmatched {ua} -> {ub}")
        print(f"               Hw 12-14 {summary(shift[bright])}")
        sel = [k for k, m in zip(keys, mags) if 12 <= m < 14]
        print(f"               Hw 12-14 accuracy: {accuracy(a, sel):.3f} mas without, {accuracy(b, sel):.3f} mas with")


if __name__ == "__main__":
    main()
