#!/bin/sh
# The solutions of the reduced three-year survey (engine/sequences/survey_3yr.toml; docs/astrometric-solution.md),
# once `jsim sequence` has run it into DIR:
#   - every K-th exposure of each stare, K = 10, 3 and 1 (≈ 100, 300 and 1000 exposures per star over the whole
#     three years), each without and with the error a visit shares (--excess-noise per-visit);
#   - the closed-form budget checked against the curve: extrapolated from one stare (42 exposures) to the
#     survey's 1008, beside the 1008 solved.
# Each solution goes to DIR/solve_…; the scoring's precision_vs_n.csv and mission_budget.csv are in each.
# Usage: survey_3yr_solve.sh DIR [JSIM]   (JSIM: the jsim binary, default `jsim` on PATH)
set -eu
dir=${1:?usage: survey_3yr_solve.sh DIR [JSIM]}
jsim=${2:-jsim}
for k in 10 3 1; do
  for excess in none per-visit; do
    "$jsim" solve --sequence "$dir" --every "$k" --excess-noise "$excess" --out "$dir/solve_every${k}_${excess}"
  done
done
"$jsim" solve --sequence "$dir" --exposures 42,1008 --mission-exposures 1008 --mission-stare-exposures 42 \
  --out "$dir/solve_budget_check"
