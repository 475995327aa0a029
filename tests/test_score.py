"""The score (Lagrange-multiplier) test: Holm correction, agreement with the likelihood ratio of a refit
for a small effect, confounded groups, absorption by time-knot coefficients, skipped candidates,
reuse of the augmented model, and the ranking's reports."""

from __future__ import annotations

import json

import numpy as np
import pytest

import rocketid as ri
from rocketid.cases import ra66m, ra66m_truth
from rocketid.diagnostics import CATALOGUE, confirm, custom_effect, rank_candidates, with_effects
from rocketid.diagnostics.score import holm
from rocketid.errors import SettingsError


@pytest.fixture(scope="module")
def base():
    return ra66m()


@pytest.fixture(scope="module")
def mesh(base):
    return ri.default_mesh(base, refine_first=3)


@pytest.fixture(scope="module")
def clean_fit(base, mesh):
    """RA-66M fitted to data without a hidden effect (seed 0)."""
    data = ri.simulate_measurements(base, ra66m_truth(base), ri.ra66_times(), seed=0)
    return ri.estimate(base, data, mesh=mesh)


@pytest.fixture(scope="module")
def clean_ranking(clean_fit):
    return rank_candidates(clean_fit)


def test_holm():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 -> 4x, 3x, 2x, 1x, running maximum
    np.testing.assert_allclose(holm(p), [0.03, 0.06, 0.06, 0.02])
    assert holm([0.9, 0.8])[0] == 1.0


def test_ranking_of_a_clean_fit(clean_ranking, clean_fit):
    r = clean_ranking
    # RA-66M's motor burns through the horizon: the power-off drag has no phase to act in, and says so; it lifts
    # off from rest, so no declared moving start is corrected
    unused = {"base_drag", "start_angle", "start_speed"}
    assert set(r.names) == set(CATALOGUE) - unused and set(r.skipped) == unused
    assert "stops inside the horizon" in r.skipped["base_drag"] and "starts at rest" in r.skipped["start_angle"]
    assert [c.rank for c in r.candidates] == list(range(1, len(CATALOGUE) - len(unused) + 1))
    # best first: p-values non-decreasing
    p = [c.p_value for c in r.candidates]
    assert all(a <= b * (1 + 1e-12) for a, b in zip(p, p[1:]))
    for c in r.candidates:
        assert c.p_value_corrected >= c.p_value
        assert c.predicted_drop == pytest.approx(c.statistic / 2)
        assert c.dof == len(CATALOGUE[c.name].realistic)
        assert c.significant == (c.p_value_corrected < 0.05)
    # the groups partition the candidates, numbered in rank order
    flat = [n for g in r.groups for n in g]
    assert sorted(flat) == sorted(r.names)
    assert [r[g[0]].group for g in r.groups] == list(range(1, len(r.groups) + 1))
    # thrust level and back-pressure move the trajectory the same way at this fit: one group
    # (the catalogue's back_pressure before issue 8 is back_pressure_vacuum now: P - A_e p_a(h))
    assert "back_pressure_vacuum" in r.group_of("thrust_level")
    # a mass-flow error of realistic size is absorbed by the Mach table of drag
    assert r["mass_flow"].absorbed_by == [f"CD_M_{j}" for j in range(7)]
    assert "confounded with CD_M(M): it would be absorbed into the drag estimate" in r["mass_flow"].note
    assert r["mass_flow"].realistic_statistic < 25
    assert "the effect would go unseen" in r["mass_flow"].note
    # a transonic drag rise is absorbed by it too, but what is left is visible at a realistic size
    assert r["transonic_drag"].absorbed_by == [f"CD_M_{j}" for j in range(7)]
    assert r["transonic_drag"].realistic_statistic > 1000 and "still detectable" in r["transonic_drag"].note
    # a sensor bias in v is not absorbed
    assert r["bias_v"].absorbed_by is None and r["bias_v"].retained > 0.9
    d = r.to_dict()
    json.dumps(d)
    first = d["candidates"][0]
    assert {"name", "statistic", "p_value", "group"} <= set(first)
    assert first["p_value"] == r.candidates[0].p_value_corrected
    s = r.summary()
    assert "Holm" in s and "Notes" in s and r.candidates[0].name in s
    assert r.timings["sensitivity_s"] < r.timings["total_s"]
    # the explained residual has each channel's shape
    for ch in clean_fit.nlp.channel_names:
        assert r.explained["bias_h"][ch].shape == clean_fit.residuals[ch].shape


def test_reusing_the_augmented_model(clean_ranking, clean_fit, base, mesh):
    again = rank_candidates(clean_fit, augmented=clean_ranking.augmented)
    assert again.timings["reused_augmented_model"] and again.timings["build_s"] == 0.0
    for a, b in zip(clean_ranking.candidates, again.candidates):
        assert a.name == b.name and a.statistic == pytest.approx(b.statistic, rel=1e-9, abs=1e-9)
    # an augmented model of other candidates is not reused
    small = rank_candidates(clean_fit, ["bias_h", "bias_v"], augmented=clean_ranking.augmented)
    assert not small.timings["reused_augmented_model"]
    assert any("does not match" in n for n in small.notes)
    assert small["bias_h"].statistic == pytest.approx(clean_ranking["bias_h"].statistic, rel=1e-6)


def test_the_score_statistic_predicts_the_refit(base, mesh):
    """For a small effect the score statistic equals the likelihood ratio of the refit, and the
    one-step estimate the refit's estimate (first-order agreement)."""
    spec = with_effects(base, ["bias_h"], {"b_h": 0.15})
    data = ri.simulate_measurements(spec, ra66m_truth(spec), ri.ra66_times(), seed=4)
    fit = ri.estimate(base, data, mesh=mesh)
    r = rank_candidates(fit, ["bias_h", "bias_v", "scale_v"])
    c = confirm(fit, "bias_h", holdout=None)
    assert r["bias_h"].statistic == pytest.approx(c.lr_statistic, rel=0.02)
    assert c.lags == max(min(20, r.size // 5) for r in fit.residuals.values())   # the lags the test used
    assert c.summary().value.section("Effect parameters (95 % interval)").items[0].rows[0][0] == "b_h"
    est, se, _ = c.effect_estimates["b_h"]
    assert abs(r["bias_h"].one_step["b_h"] - est) < 0.05 * se


def test_candidates_that_cannot_apply_are_skipped(base, mesh):
    spec = with_effects(base, ["bias_h"], {"b_h": 1.0})
    data = ri.simulate_measurements(spec, ra66m_truth(spec), ri.ra66_times(), seed=2)
    fit = ri.estimate(spec, data, mesh=mesh)

    def needs_pressure(m):
        k = m.parameter("k_p", 0.0)
        m.redefine("p_ambient", m.definition("p_ambient") * (1 + k))
        return k
    r = rank_candidates(fit, ["bias_h", "bias_x", custom_effect("pressure_scale", needs_pressure)])
    assert r.names == ["bias_x"]
    assert "already in the model" in r.skipped["bias_h"]
    assert "p_ambient" in r.skipped["pressure_scale"]
    assert "bias_h was not scored" in r.summary()
    with pytest.raises(SettingsError, match="level"):
        rank_candidates(fit, ["bias_x"], level=1.5)


def test_time_knot_coefficients_absorb_force_effects(ra66_spec, ra66_noisy_fit):
    """RA-66 (CD(t) on 7 knots): a mass-flow error is absorbed into the drag estimate."""
    r = rank_candidates(ra66_noisy_fit, ["mass_flow", "thrust_level", "bias_v"])
    c = r["mass_flow"]
    assert c.absorbed_by == [f"CD{j}" for j in range(7)]
    assert "confounded with CD(t): it would be absorbed into the drag estimate" in c.note
    assert r["bias_v"].absorbed_by is None
