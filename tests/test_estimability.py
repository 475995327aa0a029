"""Estimability (7.7)-(7.9): eigen-decomposition of H_r, np by the modified E-optimal
criterion under each scaling, estimation with q2 fixed, bad input, and the CLI command.

RA-66 numbers (H_r at p0, default mesh; ``docs/estimability.md`` has the tables): with
threshold 3000, np = 3 in physical units and np = 5 with each parameter divided by its
nominal value (CD 0.5, CL 0.1), the chapter's np.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.errors import SettingsError
from rocketid.estimability import (DEFAULT_THRESHOLD, Scaling, analyze, estimate_q1,
                                   select_np)
from rocketid.sensitivity import sensitivity_at

#: lambda_1 / lambda_k of RA-66's H_r at p0 (measured; 1 % tolerance)
RA66_RATIOS = {
    "none": [1.0, 56.64, 1589, 1.250e4, 5.661e4, 1.829e5, 2.379e6, 3.091e7],
    "nominal": [1.0, 2.576, 70.99, 549.6, 2476, 7992, 1.036e5, 1.346e6],
}
RA66_NP = {"none": 3, "nominal": 5}


@pytest.fixture(scope="module")
def p0_sensitivity(ra66_noisy_prepared):
    return sensitivity_at(ra66_noisy_prepared)


@pytest.fixture(scope="module", params=["none", "nominal"])
def analysis(request, ra66_noisy_prepared, p0_sensitivity):
    return analyze(ra66_noisy_prepared, scaling=request.param, sensitivity=p0_sensitivity)


# ---------------------------------------------------------------------------
# (7.7), (7.8) and the criterion on RA-66
# ---------------------------------------------------------------------------


def test_np_and_ratios_of_ra66_under_each_scaling(analysis):
    est = analysis
    print("\n" + est.summary().text())
    key = est.scaling.value
    assert est.n_estimated == RA66_NP[key]
    assert est.threshold == DEFAULT_THRESHOLD == 3000
    assert np.allclose(est.ratios, RA66_RATIOS[key], rtol=1e-2)
    assert np.all(np.diff(est.eigenvalues) < 0)
    assert est.ratios[est.n_estimated - 1] <= 3000 < est.ratios[est.n_estimated]
    assert est.notes == ()


def test_directions_of_ra66(analysis):
    """CL alone is the best-determined direction; CD0 and CD6 (the ends of the flight, low
    dynamic pressure) are the two worst, each nearly alone; the middle knots mix."""
    est = analysis
    comp = est.composition()
    names = list(est.parameter_names)
    assert np.allclose(comp.sum(axis=0), 1.0)
    assert np.allclose(est.V.T @ est.V, np.eye(8), atol=1e-12)
    assert comp[names.index("CL"), 0] > 0.85
    assert comp[names.index("CD0"), 7] > 0.9
    assert comp[names.index("CD6"), 6] > 0.9
    # q2 mixes the middle knots CD2..CD4 (max dynamic pressure at about 40 s)
    assert comp[[names.index(n) for n in ("CD2", "CD3", "CD4")], 1].sum() > 0.85


def test_scaling_setting_is_explicit_and_reported(analysis):
    est = analysis
    nominal = np.array([0.5] * 7 + [0.1])
    assert np.array_equal(est.D, nominal if est.scaling is Scaling.NOMINAL else np.ones(8))
    assert f"scaling       : {est.scaling.value}" in est.summary().text()
    d = est.to_dict()
    assert d["scaling"] == est.scaling.value


def test_transformed_parameters_round_trip(analysis, ra66_spec):
    est = analysis
    p = ra66_spec.guess
    q = est.q_of(p)
    assert np.allclose(est.p_of(q), p, rtol=1e-12)
    q2 = est.q2_of(p)
    tf = est.transform(q2)
    assert tf.P.shape == (8, est.n_estimated)
    assert np.allclose(tf.P @ q[:est.n_estimated] + tf.c, p, rtol=1e-12)
    with pytest.raises(SettingsError, match=f"q2 must have {8 - est.n_estimated} values"):
        est.transform(np.zeros(8))


def test_json_report(analysis, tmp_path):
    path = analysis.to_json(tmp_path / "est.json")
    d = json.loads(path.read_text())
    assert {"eigenvalues", "ratios", "np", "scaling", "threshold", "evaluated_at"} <= d.keys()
    assert d["evaluated_at"] == {"CD0": 0.1, "CD1": 0.6, "CD2": 0.1, "CD3": 0.6, "CD4": 0.1, "CD5": 0.6,
                                 "CD6": 0.1, "CL": 0.12}
    assert d["eigenvalues"] == sorted(d["eigenvalues"], reverse=True)
    assert len(d["directions"]) == 8


def test_plot(analysis, tmp_path):
    import matplotlib.pyplot as plt
    fig = analysis.plot(tmp_path / "est.png")
    assert (tmp_path / "est.png").stat().st_size > 10_000
    plt.close(fig)


# ---------------------------------------------------------------------------
# The criterion and bad input
# ---------------------------------------------------------------------------


def test_select_np():
    lam = np.array([3000.0, 30.0, 1.0, 0.5])
    assert select_np(lam, 3000) == 3            # the ratio 3000 itself is kept
    assert select_np(lam, 2999.99) == 2
    assert select_np(lam, 1.0001) == 1
    assert select_np(lam, np.inf) == 4
    assert select_np(np.array([1.0, 1e-3, 0.0, -1e-12]), 3000) == 2   # non-positive eigenvalues never
    assert select_np(np.array([0.0, 0.0]), 3000) == 0


@pytest.mark.parametrize("threshold", [1.0, 0.5, 0.0, -3000.0, float("nan")])
def test_threshold_must_exceed_one(ra66_noisy_prepared, p0_sensitivity, threshold):
    with pytest.raises(SettingsError, match="threshold of the modified E-optimal criterion must exceed 1"):
        analyze(ra66_noisy_prepared, threshold=threshold, sensitivity=p0_sensitivity)


@pytest.mark.parametrize("n", [0, 9, -1, 2.5])
def test_np_must_be_from_one_to_the_parameter_count(ra66_noisy_prepared, p0_sensitivity, n):
    with pytest.raises(SettingsError, match="np must be an integer from 1 to 8"):
        analyze(ra66_noisy_prepared, n_estimated=n, sensitivity=p0_sensitivity)


def test_forced_np_is_noted(ra66_noisy_prepared, p0_sensitivity):
    est = analyze(ra66_noisy_prepared, n_estimated=6, scaling="nominal", sensitivity=p0_sensitivity)
    assert est.n_estimated == 6
    assert est.notes == ("np = 6 was forced (the criterion with threshold 3000 gives 5)",)


def test_unknown_scaling_lists_the_choices(ra66_noisy_prepared, p0_sensitivity):
    with pytest.raises(SettingsError, match="unknown scaling 'log'; choose one of none, nominal"):
        analyze(ra66_noisy_prepared, scaling="log", sensitivity=p0_sensitivity)


def decay_with_unused_parameter() -> ri.ModelSpec:
    m = ri.Model("decay_gain_c", 0.0, 5.0)
    x = m.state("x", 0.0)
    u = m.input("u", 1 + sp.sin(2 * m.t))
    k = m.parameter("k", 0.5, bounds=(0.01, 10.0))
    g = m.parameter("g", 1.0, bounds=(0.01, 10.0))
    m.parameter("c", 1.0, bounds=(0.0, 2.0))       # enters neither the equations nor the outputs
    m.ode({x: -k * x + g * u})
    m.output("x", x, sigma=0.05)
    return m.freeze()


def test_singular_model_is_noted_and_its_null_direction_never_selected(tmp_path):
    spec = decay_with_unused_parameter()
    data = ri.simulate_measurements(spec, None, np.linspace(0.1, 5.0, 50), seed=0)
    prepared = ri.prepare(spec, data, mesh=ri.uniform_mesh(0.0, 5.0, 10, 4))
    est = analyze(prepared, threshold=1e12)
    assert est.n_estimated == 2
    assert est.eigenvalues[-1] == 0
    assert est.composition()[2, 2] == pytest.approx(1.0)
    assert any("parameter c has no effect on the outputs" in n for n in est.notes)
    assert any("H_r is singular" in n for n in est.notes)
    # the JSON stays valid: the infinite ratio is null
    d = json.loads(est.to_json(tmp_path / "singular.json").read_text())
    assert d["ratios"][2] is None


# ---------------------------------------------------------------------------
# (7.9): estimation with q2 fixed
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("scaling", ["none", "nominal"])
def test_noise_free_data_with_q2_at_the_truth_recover_q1(ra66_spec, ra66_clean, ra66_p_true, scaling):
    prepared = ri.prepare(ra66_spec, ra66_clean)
    est = analyze(prepared, scaling=scaling)           # V from p0, as the chapter
    q_true = est.q_of(ra66_p_true)
    fit = estimate_q1(prepared, est, q_true[est.n_estimated:])
    assert fit.success, fit.message
    q = est.q_of(fit.p)
    err = np.abs(q[:est.n_estimated] - q_true[:est.n_estimated])
    print(f"\nnoise-free (7.9), scaling {scaling}: |q1 - V1^T p_true| = {err.max():.2e}, "
          f"|p - p_true| = {np.abs(fit.p - ra66_p_true).max():.2e}, {fit.iterations} iterations")
    assert err.max() <= 1e-4 * np.abs(q_true[:est.n_estimated]).max()
    assert np.allclose(q[est.n_estimated:], q_true[est.n_estimated:], rtol=0, atol=1e-10)
    assert np.abs(fit.p - ra66_p_true).max() < 1e-4


def prediction_errors(spec, p, clean) -> dict[str, float]:
    """Mean absolute difference between the simulator's outputs at ``p`` and the noise-free
    truth over the 6600 samples, per channel (the chapter's Table 7.2 "average error")."""
    out = ri.simulate(spec, p, ri.ra66_times()).outputs()
    return {ch.name: float(np.mean(np.abs(out[ch.name] - ch.values))) for ch in clean.channels}


@pytest.fixture(scope="module")
def index0(ra66_noisy_prepared, p0_sensitivity, ra66_spec):
    """The chapter's 'index 0': q2 fixed at V2^T p0, nominal scaling (np = 5), data seed 0."""
    est = analyze(ra66_noisy_prepared, scaling="nominal", sensitivity=p0_sensitivity)
    q2 = est.q2_of(ra66_spec.guess)
    return est, q2, estimate_q1(ra66_noisy_prepared, est, q2)


def test_index0_solve_converges_and_predicts_better_than_p0(index0, ra66_spec, ra66_clean):
    est, q2, fit = index0
    assert fit.success, fit.message
    assert fit.iterations <= 10
    assert fit.n_estimated == 5
    errors = prediction_errors(ra66_spec, fit.p, ra66_clean)
    errors_p0 = prediction_errors(ra66_spec, ra66_spec.guess, ra66_clean)
    print("\nindex 0 (q2 = V2^T p0, nominal scaling, seed 0): "
          + ", ".join(f"{n}={v:.4f}" for n, v in zip(ra66_spec.parameter_names, fit.p))
          + f"\n  {fit.iterations} iterations, chi2/dof {fit.chi2_per_dof:.1f}"
          + "\n  prediction error (mean |y - y_true|): " + ", ".join(f"{k} {v:.4g}" for k, v in errors.items())
          + "\n  at p0 itself: " + ", ".join(f"{k} {v:.4g}" for k, v in errors_p0.items()))
    for name in errors:
        assert errors[name] < errors_p0[name] / 5
    # q2 stays where it was fixed, and p is in its bounds (the linear rows of (7.9))
    assert np.allclose(est.q2_of(fit.p), q2, rtol=0, atol=1e-10)
    assert np.all(fit.p >= ra66_spec.lower - 1e-9) and np.all(fit.p <= ra66_spec.upper + 1e-9)


def test_warm_started_resolve_after_a_change_of_q2(index0, ra66_noisy_prepared, ra66_spec):
    est, _, first = index0
    rng = np.random.default_rng(0)
    for _ in range(3):
        q2 = est.q2_of(rng.uniform(ra66_spec.lower, ra66_spec.upper))
        warm = estimate_q1(ra66_noisy_prepared, est, q2, warm_start=first)
        cold = estimate_q1(ra66_noisy_prepared, est, q2)
        assert warm.success and cold.success
        assert warm.iterations <= 8, warm.iterations
        # no NLP rebuilt: the warm path re-offsets the first solve's NLP, sharing its structure and
        # expansion matrices, while the cold path builds its own
        for structure in ("jacobianstructure", "hessianstructure"):
            assert all(a is b for a, b in zip(getattr(warm.nlp, structure)(), getattr(first.nlp, structure)()))
            assert not any(a is b for a, b in zip(getattr(cold.nlp, structure)(), getattr(first.nlp, structure)()))
        assert not np.array_equal(warm.nlp.transform.c, first.nlp.transform.c)
        assert np.allclose(warm.p, cold.p, rtol=0, atol=1e-6)
        assert np.allclose(est.q2_of(warm.p), q2, atol=1e-10)
        # the bounds of p hold exactly (linear inequality rows), active or not
        assert np.all(warm.p >= ra66_spec.lower - 1e-8) and np.all(warm.p <= ra66_spec.upper + 1e-8)


def decay_with_gain(k_upper: float = 10.0) -> ri.ModelSpec:
    m = ri.Model("decay_gain", 0.0, 5.0)
    x = m.state("x", 0.0)
    u = m.input("u", 1 + sp.sin(2 * m.t))
    k = m.parameter("k", 0.5, bounds=(0.01, k_upper))
    g = m.parameter("g", 1.0, bounds=(0.01, 10.0))
    m.ode({x: -k * x + g * u})
    m.output("x", x, sigma=0.05)
    return m.freeze()


def test_a_bound_of_p_is_an_active_linear_constraint():
    """k's upper bound 0.6 is below its true 0.8: in (7.9) the bound is a linear row on q1,
    and IPOPT holds p on it, to within its bound_relax_factor (1e-8, relative): unlike a
    variable bound (honor_original_bounds), a constraint row is not projected back."""
    spec = decay_with_gain(k_upper=0.6)
    data = ri.simulate_measurements(spec, {"k": 0.8, "g": 2.0}, np.linspace(0.1, 5.0, 50), seed=0)
    prepared = ri.prepare(spec, data, mesh=ri.uniform_mesh(0.0, 5.0, 10, 4))
    est = analyze(prepared, n_estimated=1)
    fit = estimate_q1(prepared, est, est.q2_of(spec.parameter_vector({"k": 0.5, "g": 2.0})))
    assert fit.success, fit.message
    assert fit.nlp.m_lin == 2                                # one row per bounded parameter
    assert fit.p[0] == pytest.approx(0.6, abs=2e-8)          # active
    assert np.all(fit.p <= spec.upper * (1 + 2e-8))


def test_q2_outside_the_reach_of_the_bounds_does_not_claim_success(ra66_noisy_prepared, ra66_spec):
    """The sampling algorithm draws p_trial inside the bounds, so q2 = V2^T p_trial is always
    reachable; a q2 from outside them (CD0 = 2.5) leaves (7.9) without a feasible point."""
    est = analyze(ra66_noisy_prepared, scaling="nominal", n_estimated=7)    # only the CD0 direction fixed
    p_trial = np.array(ri.ra66_truth(ra66_spec))
    p_trial[0] = 2.5
    fit = estimate_q1(ra66_noisy_prepared, est, est.q2_of(p_trial), options={"max_iter": 50})
    assert not fit.success


# ---------------------------------------------------------------------------
# rocketid estimability
# ---------------------------------------------------------------------------


def _runner() -> CliRunner:
    try:
        return CliRunner(mix_stderr=False)  # click < 8.2
    except TypeError:
        return CliRunner()


def invoke(*args):
    return _runner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def ra66_csv(tmp_path_factory, ra66_noisy):
    return ra66_noisy.to_csv(tmp_path_factory.mktemp("est") / "ra66.csv")


@pytest.mark.parametrize("scaling", ["none", "nominal"])
def test_cli_report_and_json(ra66_csv, tmp_path, scaling):
    out, png = tmp_path / "est.json", tmp_path / "est.png"
    result = invoke("estimability", ra66_csv, "--scaling", scaling, "--out", out, "--plot", png)
    assert result.exit_code == 0, result.output + result.stderr
    assert f"np            : {RA66_NP[scaling]} of 8 directions estimated" in result.output
    d = json.loads(out.read_text())
    assert {"eigenvalues", "ratios", "np", "scaling", "threshold", "evaluated_at"} <= d.keys()
    assert d["np"] == RA66_NP[scaling] and d["scaling"] == scaling and d["threshold"] == 3000
    assert np.allclose(d["ratios"], RA66_RATIOS[scaling], rtol=1e-2)
    assert d["evaluated_at"]["CD1"] == 0.6 and d["at"] == "guess"
    assert d["mesh"] == {"n_elements": 66, "K": 4}
    assert png.stat().st_size > 10_000


def test_cli_at_fit_and_threshold(ra66_csv, tmp_path):
    out = tmp_path / "est.json"
    result = invoke("estimability", ra66_csv, "--at", "fit", "--threshold", "1e5", "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    d = json.loads(out.read_text())
    assert d["at"] == "fit" and d["fit"]["success"] is True and d["threshold"] == 1e5
    assert abs(d["evaluated_at"]["CL"] - 0.1) < 1e-3           # the estimate, not the guess 0.12
    assert d["np"] == select_np(np.array(d["eigenvalues"]), 1e5)


def test_cli_model_file_and_ra66m(ra66_csv, tmp_path):
    # RA-66M has the same outputs (x, h, v): its H_r at its guess from the same file
    result = invoke("estimability", ra66_csv, "--model", "ra66m", "--np", "4", "--out", tmp_path / "m.json")
    assert result.exit_code == 0, result.output + result.stderr
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["model"] == "RA-66M" and d["np"] == 4 and "CL_alpha" in d["evaluated_at"]
    assert any("was forced" in n for n in d["notes"])


@pytest.mark.parametrize("args, message", [
    (["--threshold", "1"], "--threshold: the threshold of the modified E-optimal criterion must exceed 1"),
    (["--np", "0"], "--np must be from 1 to 8"),
    (["--np", "9"], "--np must be from 1 to 8"),
    (["--scaling", "log"], "'log' is not one of 'none', 'nominal'"),
    (["--guess", "CD9=0.5"], "'CD9' is not a parameter of model 'RA-66'"),
    (["--guess", "CL=2"], "--guess: the guess 2 of parameter CL lies outside its bounds"),
    (["--model", "ra67"], "unknown model 'ra67'"),
])
def test_cli_bad_input(ra66_csv, tmp_path, args, message):
    result = invoke("estimability", ra66_csv, *args, "--out", tmp_path / "x.json")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and message in lines[0], result.stderr
    assert not (tmp_path / "x.json").exists()


def test_cli_missing_data_file(tmp_path):
    result = invoke("estimability", tmp_path / "nope.csv", "--out", tmp_path / "x.json")
    assert result.exit_code == 2
    assert result.stderr.startswith("Error: ") and "nope.csv" in result.stderr


def test_cli_at_fit_refuses_an_unconverged_fit(ra66_csv, tmp_path):
    out = tmp_path / "est.json"
    result = invoke("estimability", ra66_csv, "--at", "fit", "--ipopt", "max_iter=1", "--out", out)
    assert result.exit_code == 1
    assert result.stderr.startswith("Error: the full fit did not converge")
    assert not out.exists()
