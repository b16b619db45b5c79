"""jsim.solve (the astrometric solution) against an independent solver: scipy's non-linear least squares
on the same observations, priors and model, written here from the model's equation alone."""

import numpy as np
import pytest
from scipy.optimize import least_squares

import jsim


def synthetic(seed=3, n=60):
    """n sources in the middle of a 3 × 3 pattern (every source seen by every pointing) at four epochs
    half a year apart; attitude errors of 200 mas, 10″ roll and 2 ppm scale; 1-mas noise; every fourth
    source in a reference catalogue with a survey's errors."""
    rng = np.random.default_rng(seed)
    truth = np.column_stack(
        [
            rng.uniform(-500, 500, n),
            rng.uniform(-500, 500, n),
            rng.normal(0, 5, n),
            rng.normal(0, 5, n),
            rng.uniform(0.05, 1.0, n),
        ]
    )
    centres = np.array([(x, y) for x in (-1000.0, 0.0, 1000.0) for y in (-1000.0, 0.0, 1000.0)])
    t, c = [], []
    for epoch in range(4):
        for k, centre in enumerate(centres):
            t.append(0.5 * epoch + 0.002 * k)
            c.append(centre)
    t, c = np.array(t), np.array(c)
    px, py = np.sin(2 * np.pi * t), 0.4 * np.cos(2 * np.pi * t)
    roll = rng.normal(0, 10 / 206264.8, len(t))
    scale = 1 + rng.normal(0, 2e-6, len(t))
    p, q = scale * np.cos(roll), scale * np.sin(roll)
    offset = rng.normal(0, 200, (len(t), 2))
    e_idx, s_idx = np.meshgrid(np.arange(len(t)), np.arange(n), indexing="ij")
    e_idx, s_idx = e_idx.ravel(), s_idx.ravel()
    xi = truth[s_idx, 0] + truth[s_idx, 2] * t[e_idx] + truth[s_idx, 4] * px[e_idx]
    eta = truth[s_idx, 1] + truth[s_idx, 3] * t[e_idx] + truth[s_idx, 4] * py[e_idx]
    dx, dy = xi - c[e_idx, 0], eta - c[e_idx, 1]
    ox = c[e_idx, 0] + p[e_idx] * dx - q[e_idx] * dy + offset[e_idx, 0] + rng.normal(0, 1, len(e_idx))
    oy = c[e_idx, 1] + q[e_idx] * dx + p[e_idx] * dy + offset[e_idx, 1] + rng.normal(0, 1, len(e_idx))
    ref = np.arange(0, n, 4)
    ref_sigma = np.array([0.3, 0.3, 0.1, 0.1, 0.05])
    ref_values = truth[ref] + rng.normal(0, 1, (len(ref), 5)) * ref_sigma
    observations = dict(exposure=e_idx, source=s_idx, xi_mas=ox, eta_mas=oy, sigma_mas=np.ones(len(ox)))
    exposures = dict(
        t_yr=t, parallax_xi=px, parallax_eta=py, centre_xi_mas=c[:, 0], centre_eta_mas=c[:, 1]
    )
    names = ["xi_mas", "eta_mas", "pm_xi", "pm_eta", "parallax"]
    references = dict(source=ref)
    for j, name in enumerate(names):
        references[name] = ref_values[:, j]
        references["sigma_" + name] = np.full(len(ref), ref_sigma[j])
    return observations, exposures, references, truth, names


def scipy_solution(observations, exposures, references, n):
    """The weighted least-squares optimum of o = c + [[p, −q], [q, p]] (s(t) − c) + a with the references
    as priors, by scipy (trust-region reflective, analytic Jacobian not used: finite differences)."""
    e, s = observations["exposure"], observations["source"]
    t, px, py = exposures["t_yr"], exposures["parallax_xi"], exposures["parallax_eta"]
    cx, cy = exposures["centre_xi_mas"], exposures["centre_eta_mas"]
    n_exp = len(t)
    ref = references["source"]
    names = ["xi_mas", "eta_mas", "pm_xi", "pm_eta", "parallax"]
    ref_values = np.column_stack([references[k] for k in names])
    ref_sigma = np.column_stack([references["sigma_" + k] for k in names])

    def residuals(x):
        src = x[: 5 * n].reshape(n, 5)
        att = x[5 * n :].reshape(n_exp, 4)
        xi = src[s, 0] + src[s, 2] * t[e] + src[s, 4] * px[e]
        eta = src[s, 1] + src[s, 3] * t[e] + src[s, 4] * py[e]
        dx, dy = xi - cx[e], eta - cy[e]
        mx = cx[e] + att[e, 0] * dx - att[e, 1] * dy + att[e, 2]
        my = cy[e] + att[e, 1] * dx + att[e, 0] * dy + att[e, 3]
        r_obs = np.concatenate(
            [(observations["xi_mas"] - mx), (observations["eta_mas"] - my)]
        ) / np.concatenate([observations["sigma_mas"]] * 2)
        r_ref = ((src[ref] - ref_values) / ref_sigma).ravel()
        return np.concatenate([r_obs, r_ref])

    # start: every source at its first observation, the attitudes the identity
    x0 = np.zeros(5 * n + 4 * n_exp)
    first = np.unique(s, return_index=True)[1]
    x0[0 : 5 * n : 5] = observations["xi_mas"][first]
    x0[1 : 5 * n : 5] = observations["eta_mas"][first]
    x0[5 * n :: 4] = 1.0
    fit = least_squares(residuals, x0, method="trf", x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15)
    return fit.x[: 5 * n].reshape(n, 5), fit.x[5 * n :].reshape(n_exp, 4)


@pytest.mark.parametrize("method", ["cg", "block"])
def test_the_solution_is_scipys_least_squares_optimum(method):
    observations, exposures, references, truth, names = synthetic()
    n = len(truth)
    sol = jsim.solve(observations, exposures, references, method=method, clip_sigma=0.0)
    assert sol["converged"]
    want, att = scipy_solution(observations, exposures, references, n)
    for j, name in enumerate(names):
        diff = np.abs(sol[name] - want[:, j]) / sol["sigma_" + name]
        # the criterion stops at 10⁻³ σ a step: what is left is of that order
        assert diff.max() < 0.01, (name, diff.max())
    # the attitudes: their turn and scale as the shift they make at the pattern's reach (10³ mas), and their
    # offsets, within 0.01 mas (their own σ ≈ 0.2 mas)
    assert np.max(np.abs(sol["p"] - att[:, 0]) * 1e3) < 0.01
    assert np.max(np.abs(sol["q"] - att[:, 1]) * 1e3) < 0.01
    assert np.max(np.abs(sol["offset_xi_mas"] - att[:, 2])) < 0.01
    assert np.max(np.abs(sol["offset_eta_mas"] - att[:, 3])) < 0.01
    # and the truth lies within the errors it reports (χ² of the positions over 2n degrees of freedom)
    z = (sol["xi_mas"] - truth[:, 0]) / sol["sigma_xi_mas"]
    assert abs(np.mean(z**2) - 1) < 5 * np.sqrt(2 / n), np.mean(z**2)


def test_bad_input_is_named():
    observations, exposures, references, _, _ = synthetic(n=12)
    with pytest.raises(ValueError, match="model"):
        jsim.solve(observations, exposures, references, model="five")
    with pytest.raises(ValueError, match="method"):
        jsim.solve(observations, exposures, references, method="fast")
    short = dict(observations, sigma_mas=observations["sigma_mas"][:-1])
    with pytest.raises(ValueError, match="sigma_mas"):
        jsim.solve(short, exposures, references)
    negative = dict(observations, source=observations["source"] - 1)
    with pytest.raises(ValueError, match="source"):
        jsim.solve(negative, exposures, references)
    with pytest.raises(ValueError, match="tolerance_sigma"):
        jsim.solve(observations, exposures, references, tolerance_sigma=2.0)
    missing = {k: v for k, v in exposures.items() if k != "t_yr"}
    with pytest.raises(ValueError, match="t_yr"):
        jsim.solve(observations, missing, references)
    with pytest.raises(ValueError, match="excess_noise"):
        jsim.solve(observations, exposures, references, excess_noise="lots")
    short_stare = dict(exposures, stare=np.zeros(len(exposures["t_yr"]) - 1))
    with pytest.raises(ValueError, match="stare"):
        jsim.solve(observations, short_stare, references, excess_noise="per-stare")


def test_the_excess_noise_leaves_the_solution_and_only_widens_its_sigmas():
    # the 36 exposures in 4 visits (one per epoch): the per-visit excess measures τ from the residuals between
    # visits and carries it into the σ (never narrower than without); the parameters do not move
    observations, exposures, references, _, names = synthetic()
    visits = dict(exposures, visit=np.repeat(np.arange(4), 9))
    plain = jsim.solve(observations, visits, references)
    with_excess = jsim.solve(observations, visits, references, excess_noise="per-visit")
    assert len(plain["excess_tau_mas"]) == 0 and len(with_excess["excess_tau_mas"]) >= 1
    for name in names:
        assert np.array_equal(plain[name], with_excess[name]), name
        assert np.all(with_excess["sigma_" + name] >= plain["sigma_" + name] * (1 - 1e-12)), name


def test_solve_sequence_writes_what_jsim_solve_writes(jsim_bin, tmp_path):
    # a small step-stare sequence run by the CLI, then solved twice from its products: by `jsim solve` and by
    # jsim.solve_sequence (the same engine study) — the same files, byte for byte, and one summary per N
    import subprocess

    spec = tmp_path / "seq.toml"
    spec.write_text('[sequence]\nstares_l = 2\nstares_b = 1\nexposures_per_stare = 2\n'
                    'visits_utc = ["2031-03-21T00:00:00"]\nvisit_dither_px = 0.0\n')
    sets = []
    for s in ['ace.case="gaussian"', "instrument.detector_px=256", "instrument.photosensitive_px=240",
              "readout.channels=2", "readout.channel_width_px=128", "optics.pupil_samples=64",
              "optics.psf_oversampling=8", "optics.psf_radius_px=8", "band.wavelength_step_um=0.1",
              "fidelity.subpixels=4", "fidelity.stamp_radius_px=8", 'fidelity.backend="cpu"', "ace.span_s=60.0",
              "focal_plane.gap_px=40.0", "scene.bulge.density_per_arcmin2=40.0"]:
        sets += ["--set", s]
    seq = tmp_path / "seq"
    subprocess.run([jsim_bin, "sequence", "--countermeasure", "none", "--spec", str(spec), *sets,
                    "--out", str(seq)], check=True, capture_output=True)
    subprocess.run([jsim_bin, "solve", "--sequence", str(seq), "--exposures", "2,4", "--out", str(tmp_path / "cli")],
                   check=True, capture_output=True)
    r = jsim.solve_sequence(str(seq), exposures=[4, 2], out=str(tmp_path / "py"))
    assert [s["exposures"] for s in r["summary"]] == [2, 4]
    assert r["summary"][1]["converged"] is True
    for f in ["sources.csv", "attitudes.csv", "calibration.csv", "score_sources.csv", "score_attitudes.csv",
              "calibration_map.csv", "precision_vs_n.csv"]:
        assert (tmp_path / "py" / f).read_bytes() == (tmp_path / "cli" / f).read_bytes(), f
    with pytest.raises(ValueError, match="exposures 9: allowed 1 … 4"):
        jsim.solve_sequence(str(seq), exposures=[9], out=str(tmp_path / "bad"))
    assert not (tmp_path / "bad").exists()
    with pytest.raises(ValueError, match="model"):
        jsim.solve_sequence(str(seq), model="proper")
    # thinned, with the excess noise: the CLI's files again
    subprocess.run([jsim_bin, "solve", "--sequence", str(seq), "--every", "2", "--excess-noise", "per-stare",
                    "--out", str(tmp_path / "cli2")], check=True, capture_output=True)
    r = jsim.solve_sequence(str(seq), every=2, excess_noise="per-stare", out=str(tmp_path / "py2"))
    assert r["summary"][0]["exposures"] == 2 and r["summary"][0]["excess_noise"] == "per-stare"
    for f in ["sources.csv", "attitudes.csv", "score_sources.csv", "precision_vs_n.csv"]:
        assert (tmp_path / "py2" / f).read_bytes() == (tmp_path / "cli2" / f).read_bytes(), f
    with pytest.raises(ValueError, match="excess_noise"):
        jsim.solve_sequence(str(seq), excess_noise="lots")
