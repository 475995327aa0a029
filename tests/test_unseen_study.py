"""``rocketid diagnose`` on a vehicle and hidden effects the team never tuned on (issue 8).

Kestrel-S (``tests/vehicles/kestrel.py``) is a guided solid sounding rocket declared from the user
documentation: a tabulated regressive thrust curve, the mass as a state, a rail launch at 35 m/s,
CD and the lift slope as Mach tables, a sampled pitch program with the attack angle
``theta_cmd - theta``, 25 Hz data with per-channel sigmas. Its truth (``tests/unseen_study/truth.py``)
is written in another state space (velocity components) with every hidden effect in its own shape.

The normal suite checks the instruments (about 15 s): the truth without effects reproduces the
estimation model, the pressure table reproduces the 1976 standard, the vehicle fits clean data to
the noise, and every hidden effect changes the flight by a stated amount. The diagnoses run
``rocketid diagnose`` from the command line, one per case (10 s to a few minutes each), and are
``slow``: ``pytest -m slow tests/test_unseen_study.py``. The results table and the command that
made it are in docs/effects.md ("Evaluation on an unseen vehicle").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import kestrel as K

import rocketid as ri
from rocketid.physics.atmosphere import us76_pressure
from unseen_study import truth
from unseen_study.run import STUDY
from unseen_study.cases import ALL, CASES, Hidden

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "h-bias-drift": "a570929: bias_h_drift finds the drift (2.88 m + 0.147 m/s t for 3 + 0.15) at chi2/dof 1.086 "
                    "against the band 1.082: partly explained -- the data's own noise draw is above the band (the "
                    "exact truth leaves chi2/n 1.084 on them, seed 307), so no model can reach it",
    "back-pressure+headwind": "5e37825 to 675ca74: a spurious misalignment (0.43 deg) added first, then "
                              "back_pressure and wind; chi2/dof 1.043, h not white, partly explained -- the case's "
                              "noise draw itself is not white in h (the exact truth: Ljung-Box p 1.1e-4), so no "
                              "model is explained; the second path's true pair wind_pl_14 + back_pressure (1.0396) "
                              "has the higher BIC",
    "sliver-tailoff+h-bias-drift": "ed8bbbc (fresh pair): thrust_profile_9 + bias_v + start_angle at chi2/dof 1.157, "
                                   "partly explained, a wrong family not called explained: with bias_h_drift in at "
                                   "step 2 (1.010) the 9-knot thrust profile went to 7-14 times its realistic size; "
                                   "the truth's families, throttle_step + bias_h_drift, reach 1.008 from the base fit "
                                   "(3.11 m + 0.141 m/s t for 3 + 0.15, a 5.6 % step at 33.06 s for the 6 % ramp "
                                   "from 30 to 36 s) but v is not white (Holm p 1.8e-4): the ramp is not a step",
    "jet+heavy-start": "ed8bbbc (fresh pair): wind_pl_14 at step 1 (chi2/dof 1.421), then start_mass (25.8 kg for "
                       "25), thrust_level and back_pressure_vacuum all reach the noise within BIC 0.7 of each other "
                       "(x, h and v see thrust and mass only through their ratio): the tie named, nothing added, "
                       "partly explained",
    "earth-rotation+h-bias-drift": "ed8bbbc (fresh pair): bias_h_drift (-3.80 m + 0.093 m/s t for -4 + 0.1) at step 1 "
                                   "(chi2/dof 1.058), then earth_rotation (k_rot 1.14, 1.007) and a 0.04 deg "
                                   "misalignment (1.008) reach the noise within BIC 4.2: the tie named, partly "
                                   "explained",
}


@pytest.fixture(scope="module")
def kestrel_spec():
    return K.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), K.sample_times())


def test_truth_reproduces_the_vehicle_model(kestrel_spec):
    """Velocity components and vector forces (truth) against speed and path angle (model): < 1 mm."""
    times = K.sample_times()
    exact = truth.exact_outputs(Hidden(), times)
    model = ri.simulate(kestrel_spec, K.truth(kestrel_spec), times).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(exact[name] - model[name])) < 1e-3, name


def test_pressure_table_is_the_1976_standard():
    """The truth's own hydrostatic integration against the standard's pressure, 0-30 km."""
    hs, p, _ = truth.pressure_table()
    standard = np.array([float(us76_pressure(h)) for h in hs])
    assert np.max(np.abs(p / standard - 1)) < 2e-5


def test_vehicle_fits_clean_data_to_the_noise(kestrel_spec):
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(kestrel_spec, data)
    assert fit.success, fit.message
    dof = fit.n_data - fit.n_estimated             # n_samples counts every value of every channel
    assert abs(fit.chi2_per_dof - 1) < 4 * math.sqrt(2 / dof)
    for name, true in K.truth(kestrel_spec).items():
        assert abs(fit.value(name) / true - 1) < 0.03, name


@pytest.mark.parametrize("hidden, channel, low, high", [         # measured: the largest change
    (Hidden(hot_motor=1.03), "h", 400.0, 1000.0),                 # 684 m
    (Hidden(A_e=0.05), "v", 60.0, 150.0),                          # 95.7 m/s
    (Hidden(wind=(5.0, 20.0)), "x", 300.0, 800.0),                 # 520 m
    (Hidden(warm_dT=8.0), "v", 1.0, 2.5),                          # 1.49 m/s
    (Hidden(delta=math.radians(0.3)), "x", 20.0, 50.0),            # 32 m
    (Hidden(rotation=(69.3, 45.0)), "x", 2.0, 6.0),                # 3.6 m
    (Hidden(dm0=25.0), "v", 15.0, 40.0),                           # 25.7 m/s
    (Hidden(bias_h=(3.0, 0.15)), "h", 8.99, 9.01),                 # 3 + 0.15 * 40 m
    (Hidden(tau=0.02), "v", 0.35, 0.8),                            # 0.55 m/s
    (Hidden(drag_bump=(0.08, 1.15, 0.12)), "h", 20.0, 50.0),       # 33 m
    (Hidden(tailoff=(0.06, 30.0, 36.0)), "v", 10.0, 25.0),         # 16 m/s
    (Hidden(jet=(3.0, 30.0, 9000.0, 2500.0)), "x", 150.0, 600.0),  # the jet alone
])
def test_each_hidden_effect_changes_the_flight(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount (largest change in range)."""
    base = clean_outputs[channel]
    moved = truth.exact_outputs(hidden, K.sample_times())[channel]
    change = float(np.max(np.abs(moved - base)))
    assert low < change < high, change


def test_the_h_bias_drift_noise_draw_is_above_the_band():
    """The measured reason of KNOWN_FAILURES["h-bias-drift"]: the exact truth (the hidden drift included)
    leaves chi2/n above the 99.9 % noise band on the case's own data, so no model can be called at the noise."""
    from scipy import stats
    from unseen_study.cases import BY_NAME
    case = BY_NAME["h-bias-drift"]
    data = truth.measurements(case.hidden, case.seed)
    exact = truth.exact_outputs(case.hidden, K.sample_times())
    chi2 = sum(float(np.sum(((c.values - exact[c.name]) / K.SIGMA[c.name]) ** 2)) for c in data.channels)
    n = sum(c.values.size for c in data.channels)
    dof = n - len(K.build_model().parameter_names) - 2
    assert chi2 / n > stats.chi2.isf(1e-3, dof) / dof, chi2 / n


def test_the_back_pressure_headwind_noise_draw_is_not_white():
    """The measured reason of KNOWN_FAILURES["back-pressure+headwind"]: the exact truth (both hidden effects
    included) leaves the altitude channel's noise draw not white by the acceptance rule's own test on the case's
    data (Ljung-Box p 1.1e-4 in h, 3.2e-4 Holm-corrected over the channels, against the level 1e-3), so no
    model can be called explained there; the search's models stop at the same h (chi2/dof 1.040-1.043)."""
    from rocketid.diagnostics.accept import whiteness_ok
    from rocketid.diagnostics.refit import ljung_box
    from unseen_study.cases import BY_NAME
    case = BY_NAME["back-pressure+headwind"]
    data = truth.measurements(case.hidden, case.seed)
    exact = truth.exact_outputs(case.hidden, K.sample_times())
    white = {c.name: float(ljung_box((c.values - exact[c.name]) / K.SIGMA[c.name])[1]) for c in data.channels}
    ok, detail = whiteness_ok(white)
    assert not ok and min(white, key=white.get) == "h", detail
    assert white["x"] > 0.05 and white["v"] > 0.05, white


def test_a_misalignment_that_carried_a_coarse_wind_is_dropped_for_the_finer_wind():
    """Fresh pair heavy-start+headwind (a start mass 25 kg heavy and a headwind growing from 5 to 25 m/s): its
    search took the catalogue's 4-function wind at step 1 (the knotted winds were then 90 m/s at the surface,
    carrying the start mass), the start mass at step 2 and a 0.40 deg thrust misalignment at step 3, at the
    noise (chi2/dof 1.010) -- a wrong effect called explained: the misalignment took up the coarse wind's misfit.
    The finer shape (step module note 8) also tries a search that ended explained with three effects: the wind
    one and two rungs up without the last effect. The 6-knot wind with the start mass explains the data at a
    lower BIC, the start mass within 10 % of the truth, the surface wind within 2.5 m/s of it and the knots the
    data hold growing as the truth's headwind does."""
    from rocketid.diagnostics import step as S
    from rocketid.diagnostics.effects import CATALOGUE
    from study_harness import SetCheck
    from unseen_study.cases import BY_NAME

    case = BY_NAME["heavy-start+headwind"]
    data = truth.measurements(case.hidden, case.seed)
    base = ri.estimate(K.build_model(), data)
    check = SetCheck(base)
    ctx = check.ctx
    found = [CATALOGUE["wind"], CATALOGUE["start_mass"], CATALOGUE["misalignment"]]
    last = check.judge(found)
    assert last.accepted, [c.name for c in last.checks if not c.passed]
    effects, acc, why = S._finer(found, last, base, found, ctx)
    assert [e.name for e in effects] == ["wind_pl_6", "start_mass"], why
    assert acc.accepted and "without misalignment" in why, why
    # the backward check from that set's own fit keeps both: neither explains the data alone
    fit = S._fit_of(ctx.base_spec, effects, acc.refit, data, base.prepared.transcription.mesh, None)
    assert S._without_one(ctx, base, fit, effects, acc) is None
    r = acc.refit
    assert abs(r.estimate("dm_start")[0] - 25.0) < 2.5
    # the truth's headwind grows from 5 m/s at the ground towards 25 m/s aloft: so do the knots the data hold
    # (W_5, at the top of the climb, is loose: +-2.5 m/s)
    w = [r.estimate(f"W_{j}")[0] for j in range(5)]
    assert abs(w[0] + 5.0) < 2.5, w
    assert all(-25.5 < a < -3.0 for a in w) and all(b < a for a, b in zip(w, w[1:])), w


def test_classification_rules():
    """The outcome classes: a wrong family called explained is the worst outcome."""
    case = next(c for c in CASES if c.name == "back-pressure")
    final = {"effects": ["back_pressure"], "verdict": "explained", "parameters": {}}
    assert STUDY.classify(case, {"final": final}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["thrust_level"]}}) == "WRONG called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["thrust_level"], "verdict": "partly explained"}}) \
        == "wrong, not called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": []}}) == "nothing found"
    assert STUDY.classify(case, {"final": {**final, "verdict": "partly explained"}}) == "right but partly"
    clean = next(c for c in CASES if c.name.startswith("clean"))
    assert not STUDY.acceptable(clean, {"final": {**final}})


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_unseen_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose`` (CLI) on the case: clean data add nothing, an effect the base fit does
    not show may go unfound, a visible one is found and explained, and a wrong family is never
    reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)
