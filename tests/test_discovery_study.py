"""The hidden-effect study on independent data (issue 8): does ``diagnose`` find what is hidden?

Data come from :func:`rocketid.simulate` on truth models written independently of the effect
catalogue (``tests/discovery_study/truth.py``: back-pressure from an integrated pressure table and
a sea-level thrust, wind as an air-relative velocity with a surface wind and a jet between the
basis altitudes, misalignment from t = 0, a tanh density profile, Coriolis as cross products,
sensor effects applied to the measurements), on three vehicles: RA-66 (time knots), RA-66M and
Stage-30, a 30 t stage declared in ``tests/vehicles/stage30.py`` as a user would. The cases are
data (``tests/discovery_study/cases.py``); the table of the whole study is made by
``python benchmarks/discovery_study.py`` and quoted in docs/effects.md.

Required of every case (``harness.score``): the final model holds the true effects, reaches the
noise (chi2/dof < 1.05) with the verdict "explained" and scalar sizes within 25 % (or 3 std) of
the truth; no wrong effect is ever reported as explained; on 20 clean seeds at most one adds an
effect.

The normal suite checks the study's instruments (the pressure table, the truth models against the
vehicles' estimation models, the user's vehicle fitting clean data to the noise; about 35 s);
the diagnosis cases take 0.5-3 min each and are ``slow`` (``pytest -m slow``), the quickest being
``test_quick_case``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from discovery_study import cases as C
from discovery_study import harness as H
from discovery_study import truth as T
from discovery_study.paths import STAGE30, load_stage30

# -------------------------------------------------------------------------------------------------
# the instruments
# -------------------------------------------------------------------------------------------------


def test_pressure_table_matches_the_standards_layer_pressures():
    """The integrated table reproduces the 1976 standard's published base pressures (geopotential
    11, 20, 32 km = geometric 11 019.1, 20 063.1, 32 161.9 m) within 2e-4 after interpolation."""
    h = sp.Symbol("h")
    p = sp.lambdify(h, T.tabulated_pressure(h))
    for z, ref in ((0.0, 101325.0), (11019.1, 22632.06), (20063.1, 5474.89), (32161.9, 868.019)):
        assert p(z) == pytest.approx(ref, rel=2e-4)
    # and it rises: the back-pressure truth's thrust gains A_e (p0 - p) with altitude
    assert p(30000.0) < p(10000.0) < p(0.0)


@pytest.mark.parametrize("vehicle", ["ra66", "ra66m", "stage30"])
def test_truth_without_effects_is_the_base_model(vehicle):
    """The truth, written in another shape, and the vehicle's estimation model at its true
    parameters give the same trajectory (to 5 mm, 5 mm/s) when no effect is hidden."""
    veh = T.VEHICLES[vehicle]()
    times = np.linspace(0.5, 66.0, 132)
    truth = ri.simulate(T.truth_model(veh, {}), times=times)
    if vehicle == "stage30":
        s30 = load_stage30()
        spec = s30.build_model().freeze()
        p = s30.truth(spec)
    elif vehicle == "ra66m":
        from rocketid.cases import ra66m, ra66m_truth
        spec = ra66m()
        p = ra66m_truth(spec)
    else:
        spec = ri.ra66()
        p = ri.ra66_truth(spec)
    base = ri.simulate(spec, p, times)
    assert truth.success and base.success
    for i, name in enumerate(("x", "h", "v")):
        np.testing.assert_allclose(truth.states[:, i], base.states[:, i], atol=5e-3, rtol=0, err_msg=name)


@pytest.mark.slow
def test_hidden_effects_change_the_trajectory_the_intended_way():
    """Signs and sizes of the truth's effects on Stage-30, from their physics: back-pressure adds
    thrust with altitude (up to A_e p0 = 60.8 kN), a tailwind lowers the air-relative speed, the
    density profile is -3.3 % at the pad and 0 at 8 km, Earth rotation (east) lifts the trajectory."""
    veh = T.stage30_vehicle()
    times = np.array([20.0, 66.0])
    base = ri.simulate(T.truth_model(veh, {}), times=times)
    bp = ri.simulate(T.truth_model(veh, {"back_pressure": C.BP30}), times=times)
    thrust = bp.value("P")
    assert thrust[0] > veh.thrust and thrust[-1] == pytest.approx(veh.thrust + 0.6 * 101325.0, rel=2e-2)
    assert bp.states[-1, 2] > base.states[-1, 2] + 50.0
    wind = ri.simulate(T.truth_model(veh, {"wind": C.WIND30}), times=times)
    assert wind.value("mach_air")[0] < base.value("mach_air")[0]
    assert T.density_deviation(0.0, amplitude=0.06) == pytest.approx(-0.035, abs=1e-3)
    assert T.density_deviation(8000.0, amplitude=0.06) == 0.0
    rot = ri.simulate(T.truth_model(veh, {"earth_rotation": C.ROTATION}), times=times)
    assert rot.states[-1, 3] > base.states[-1, 3]


@pytest.mark.slow
def test_sensor_effects_are_applied_to_the_measurements():
    veh = T.stage30_vehicle()
    clean = T.measure(veh, {}, 0, noise=False)
    biased = T.measure(veh, {"bias_h": {"b_h": 5.0}, "scale_v": {"k_v": 1e-3}}, 0, noise=False)
    np.testing.assert_allclose(biased["h"].values - clean["h"].values, 5.0, atol=1e-9)
    np.testing.assert_allclose(biased["v"].values / clean["v"].values - 1, 1e-3, atol=1e-12)
    late = T.measure(veh, {"time_offset": {"tau": 0.01}}, 0, noise=False)
    # z(t) = y(t - tau): one 10 ms sample late
    np.testing.assert_allclose(late["v"].values[1:], clean["v"].values[:-1], atol=1e-6)


def test_stage30_model_file_fits_clean_data_to_the_noise():
    """The user's vehicle estimates to the noise on data without a hidden effect."""
    case = C.BY_ID["s30-clean-100"]
    from rocketid.cases.files import load_model_file
    spec, module = load_model_file(STAGE30)
    fit = ri.estimate(spec, H.read_case_csv(case), mesh=ri.default_mesh(spec, refine_first=3))
    assert fit.success
    dof = fit.n_data - fit.n_estimated
    assert abs(fit.chi2_per_dof - 1) < 4 * math.sqrt(2 / dof) + 0.005, fit.chi2_per_dof
    truth = module.truth(spec)
    for name, value in zip(spec.parameter_names, truth):
        assert fit.value(name) == pytest.approx(value, rel=0.02), name


# -------------------------------------------------------------------------------------------------
# the study
# -------------------------------------------------------------------------------------------------


def _explain(rec: dict) -> str:
    f, s = rec["final"], rec["score"]
    sizes = "; ".join(f"{k} {v['estimate']} (truth {v['truth']})" for k, v in s["sizes"].items())
    return (f"{rec['case']}: truth {rec['truth']} -> found {f['effects'] or 'nothing'}, verdict {f['verdict']!r}, "
            f"chi2/dof {f['chi2_per_dof']:.4f} (base {rec['base']['chi2_per_dof']:.4f}), sizes {sizes}; "
            f"wrong {s['wrong']}; {rec['seconds']:.0f} s; {f['api']}")


_RECORDS: dict[str, dict] = {}


def record(case_id: str) -> dict:
    """The case's diagnosis, run once per test session."""
    if case_id not in _RECORDS:
        _RECORDS[case_id] = H.run_case(C.BY_ID[case_id])
    return _RECORDS[case_id]


def check_case(rec: dict) -> None:
    s = rec["score"]
    # never a wrong effect called explained
    assert not s["wrong_explained"], _explain(rec)
    if s.get("at_data_limit"):
        # a case its data cannot show (harness.DATA_LIMITS, re-measured by test_the_data_limits_hold): nothing
        # outside the truth, and the explanation names every true effect
        assert not s["wrong"], _explain(rec)
        assert all(t in rec["final"]["explanation"] for t in rec["true_effects"]), rec["final"]["explanation"]
        return
    assert s["holds_truth"], _explain(rec)
    assert not s["wrong"], _explain(rec)
    assert s["noise"] and rec["final"]["verdict"] == "explained", _explain(rec)
    for par, v in s["sizes"].items():
        assert v["ok"], f"{par}: " + _explain(rec)


def test_a_constant_found_as_a_profile_is_scored_knot_by_knot():
    """A +1.5 % thrust error found as ``thrust_profile_5`` (measured, v-s30-thrust_level+wind+bias_h on e63c187:
    0.0149, 0.0167, 0.0114, 0.0160, 0.0171) has the truth's size when every knot agrees with it; one knot
    off by more than SIZE_TOL and 3 std is a wrong size."""
    case = C.BY_ID["v-s30-thrust_level+wind+bias_h"]
    knots = {"eps_P0": (0.01494, 0.00081), "eps_P1": (0.01669, 0.00767), "eps_P2": (0.01135, 0.00627),
             "eps_P3": (0.01599, 0.00502), "eps_P4": (0.01712, 0.0028)}
    final = {"effects": ["wind_pl_10", "thrust_profile_5", "bias_h"], "chi2_per_dof": 1.0029, "verdict": "explained",
             "parameters": {**{k: {"value": v, "std": sd} for k, (v, sd) in knots.items()},
                            "b_h": {"value": 4.985, "std": 0.062}}}
    sc = H.score(case, final)
    assert sc["sizes"]["eps_thrust"]["ok"] and sc["sizes"]["eps_thrust"]["estimate"] == [v for v, _ in knots.values()]
    assert sc["passed"] and not sc["wrong"]
    final["parameters"]["eps_P2"] = {"value": 0.03, "std": 0.002}
    assert not H.score(case, final)["sizes"]["eps_thrust"]["ok"]
    del final["parameters"]["eps_P2"], final["parameters"]["eps_P0"]
    final["parameters"]["eps_thrust"] = {"value": 0.0151, "std": 1e-5}      # the scalar, when estimated, decides
    assert H.score(case, final)["sizes"]["eps_thrust"]["estimate"] == 0.0151


@pytest.mark.slow
def test_quick_case():
    """The quickest case (about 30-80 s): a 5 m altitude bias on Stage-30, on the default mesh.

    (On 2 s elements, main e1788b4, the same data gave bias_h at chi2/dof 1.0033 with the verdict
    "partly explained"; the study uses the default mesh throughout.)
    """
    check_case(record("s30-bias_h"))


#: Cases the diagnosis did not pass when the study was last run (``benchmarks/discovery_study.py``,
#: 2026-11-24, the table in docs/effects.md: the diagnostics of 1266e7a, re-run rows on a570929), each with
#: its measured failure. They stay real assertions: xfail, not strict, so that a fix shows as XPASS.
#: (s30-back_pressure+wind passes since every significant family is refined and the exchange step;
#: at the data's limit, named in the verdict (harness.DATA_LIMITS): m-mass_flow, s30-density.)
KNOWN_FAILURES: dict[str, str] = {
    "m-thrust_level+density": "a570929: thrust_level and start_mass both reach the noise (chi2/dof 1.01, BIC within "
                              "10) while the density profile is missing, and the hold-out does not decide (start_mass "
                              "16.9, thrust_level 35.1 sigma^2: more than a quarter): 'not explained by the "
                              "catalogue', the two named as rivals (1266e7a, deciding at a half, called start_mass "
                              "explained)",
}


def _noiseless_chi2(case_id: str, added=()) -> float:
    """chi2 that the case's estimation model (with ``added`` catalogue effects) leaves on the truth's
    noiseless data: the non-centrality any test of those shapes has to work with."""
    from rocketid.diagnostics import with_effects
    from rocketid.diagnostics.api import resolve_model
    case = C.BY_ID[case_id]
    spec, _ = resolve_model(H.model_of(case))
    spec = with_effects(spec, list(added)) if added else spec
    meas = T.measure(T.VEHICLES[case.vehicle](), case.effects, case.seed, noise=False)
    fit = ri.estimate(spec, meas, mesh=ri.default_mesh(spec, refine_first=3))
    assert fit.success
    return float(2 * fit.objective)


@pytest.mark.slow
def test_the_data_limits_hold():
    """The argument of harness.DATA_LIMITS, re-measured from the truth simulator (docs/effects.md).

    m-mass_flow: the base model fitted to noiseless truth data leaves chi2 = 3.7, so even a test of
    the exact true shape (one parameter) detects it in under half of the data sets at the 5 % level.
    s30-density: the catalogue's density and wind profiles (4 parameters each) both take the base
    model's 89 to under 5 and within 3 of each other, well inside the noise of their difference."""
    from scipy import stats
    lam = _noiseless_chi2("m-mass_flow")
    assert 1.0 < lam < 6.0, lam
    assert stats.ncx2.sf(stats.chi2.isf(0.05, 1), 1, lam) < 0.6
    base = _noiseless_chi2("s30-density")
    dens = _noiseless_chi2("s30-density", ["density"])
    wind = _noiseless_chi2("s30-density", ["wind"])
    assert base > 50 and dens < 5 and wind < 5, (base, dens, wind)
    spread = 2 * (math.sqrt(dens) + math.sqrt(wind))       # sd bound of the chi2 difference on noisy data
    assert abs(wind - dens) < 0.5 * spread, (dens, wind, spread)


#: cases where the diagnosis called a wrong effect explained in the last run (m-transonic_drag was
#: one until the verdict required the final model to pass the coefficient and size checks)
KNOWN_WRONG: dict[str, str] = {}


def _cases(cases):
    return [pytest.param(c.id, marks=pytest.mark.xfail(reason=KNOWN_FAILURES[c.id], strict=False))
            if c.id in KNOWN_FAILURES else c.id for c in cases]


@pytest.mark.slow
@pytest.mark.parametrize("case_id", _cases(C.SINGLE + C.PAIRS))
def test_hidden_effect_case(case_id):
    check_case(record(case_id))


#: The varied cases (other signs and sizes, a headwind, another launch site, three effects at once; not tuned
#: on) the diagnosis did not pass when they were first run, each with its measured failure (docs/effects.md,
#: "Varied cases").
KNOWN_VARIED: dict[str, str] = {
    "v-m-thrust_level": "thrust_level and start_mass both reach the noise (chi2/dof 0.989, BIC within 10); the "
                        "hold-out window does not reach CD_M_6, so its predictions (start_mass 4.02, thrust_level "
                        "24.2 sigma^2) decide nothing: the two named as rivals, nothing added (headed 'not explained "
                        "by the catalogue' then; a first-step tie is 'partly explained' since 2026-11-28; before the "
                        "rule: start_mass called explained)",
    "v-s30-density-neg": "density explained (chi2/dof 1.004, the non-identifiable direction of its profile named), "
                         "CD_6 0.239 for 0.27 (11 %, 5 std)",
}


@pytest.mark.slow
@pytest.mark.parametrize("case_id", [pytest.param(c.id, marks=pytest.mark.xfail(reason=KNOWN_VARIED[c.id], strict=False))
                                     if c.id in KNOWN_VARIED else c.id for c in C.VARIED])
def test_varied_case(case_id):
    check_case(record(case_id))


@pytest.mark.slow
@pytest.mark.parametrize("case_id", [pytest.param(c.id, marks=pytest.mark.xfail(reason=KNOWN_WRONG[c.id], strict=False))
                                     if c.id in KNOWN_WRONG else c.id for c in C.SINGLE + C.PAIRS])
def test_no_wrong_effect_is_called_explained(case_id):
    """Whatever the diagnosis misses, it must not call a wrong effect explained (xfail only where a
    run measured it, :data:`KNOWN_WRONG`)."""
    rec = record(case_id)
    assert not rec["score"]["wrong_explained"], _explain(rec)


@pytest.mark.slow
@pytest.mark.parametrize("case_id", [c.id for c in C.CLEAN_REF])
def test_clean_reference_case_adds_nothing(case_id):
    rec = H.run_case(C.BY_ID[case_id])
    assert not rec["final"]["effects"], _explain(rec)
    assert rec["final"]["verdict"] == "nothing missing", _explain(rec)


@pytest.mark.slow
def test_at_most_one_of_20_clean_seeds_adds_an_effect():
    recs = [H.run_case(c) for c in C.CLEAN]
    added = [_explain(r) for r in recs if r["final"]["effects"]]
    assert len(added) <= 1, "\n".join(added)
    # and none of them is called explained with a wrong effect
    assert not any(r["score"]["wrong_explained"] for r in recs), "\n".join(added)
