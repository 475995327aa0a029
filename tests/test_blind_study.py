"""``rocketid diagnose`` on a second unseen vehicle, written blind (issue 8).

Halcyon-8 (``tests/vehicles/halcyon.py``) is an 8 t liquid first stage declared from the user
documentation alone: a sea-level thrust from a static firing, a linear mass history, an 8-knot
CD(Mach) table, ``CL_alpha alpha`` with a sampled pitch program and an excitation, a rail exit at
20 m/s, x, h, v at 10 Hz. Its truth (``tests/blind_study/truth.py``) was written by a team member
who did not read the diagnostics or the other studies' truth models: Earth-centred Cartesian
position and velocity, vector forces, its own 1976 atmosphere, SciPy's DOP853. The right
catalogue families of every case were written down before any diagnosis ran
(``tests/blind_study/cases.py``).

The normal suite checks the instruments: the truth without effects reproduces the estimation
model, and the vehicle fits clean data to the noise. The diagnoses (``rocketid diagnose`` from the
command line, 6 s to 7 minutes each) are ``slow``: ``pytest -m slow tests/test_blind_study.py``.
The table is in docs/effects.md ("Evaluation on a blind vehicle").
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent

import halcyon  # noqa: E402

import rocketid as ri  # noqa: E402
from rocketid.estimability import uncertainty  # noqa: E402

from blind_study import cases as C  # noqa: E402
from blind_study import run, truth  # noqa: E402

#: Cases measured not to meet the bar, with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "dropped_mass": "3cf8036 and c30ae37: 150 kg released at 55 s: mass_jettison (162 kg at 54.98 s, chi2/dof 0.968) and "
                    "throttle_step (a 3.1 % throttle-up at 54.98 s, 0.972) are within BIC 10 and the hold-out, fitted "
                    "on the first 54 s, ends before the event: the verdict names both and cannot tell them apart "
                    "(nothing found, not a wrong call); 0b4a245: the same, and a hold-out fitted on 0-65 s does not "
                    "decide either (1.56 against 3.11 sigma^2)",
}


def test_truth_reproduces_the_vehicle_model():
    """Cartesian position and velocity with vector forces (truth) against speed and path angle
    (the model, simulated by rocketid): below a millimetre."""
    spec = halcyon.build_model()
    exact = truth.simulate(run.TIMES)
    model = ri.simulate(spec, halcyon.truth(spec), run.TIMES).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(exact[name] - model[name])) < 1e-3, name


def test_vehicle_fits_clean_truth_data_to_the_noise():
    spec = halcyon.build_model()
    data = _measurements(truth.measurements(run.TIMES, {}, seed=11), spec)
    fit = ri.estimate(spec, data)
    assert fit.success, fit.message
    assert 0.9 < fit.chi2_per_dof < 1.1
    se = uncertainty(fit).standard_errors
    true = halcyon.truth(spec)
    for name, value, s in zip(spec.parameter_names, fit.p, se):
        assert abs(value - true[name]) < 4 * s, (name, value, true[name], s)


@pytest.mark.parametrize("hidden, shape, time_name, when", [
    ({"drop": {"t": 55.0, "dm": 150.0}}, "mass_jettison", "t_jettison", 55.0),
    ({"misalign": {"delta": math.radians(0.2), "t_on": 20.0}}, "misalignment_onset", "t_misalign", 20.0),
    ({"throttle": {"depth": 0.06, "t_on": 40.0, "t_off": 200.0, "ramp": 2.0}}, "throttle_step", "t_step", 41.0),
])
def test_the_onset_scan_starts_a_refit_near_the_event(hidden, shape, time_name, when):
    """The truth's events (its own vector dynamics, not the catalogue's expressions): the onset scan of the
    event shape, at the base fit, puts one of its starts within 2.5 s (one scan interval) of the event --
    for the dropped mass although the fit has absorbed it and the profile peaks elsewhere."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.score import onset_starts
    from rocketid.diagnostics.screen import vehicle_of

    spec = halcyon.build_model()
    fit = ri.estimate(spec, _measurements(truth.measurements(run.TIMES, hidden, seed=5), spec))
    family = {"mass_jettison": "start_mass", "misalignment_onset": "misalignment", "throttle_step": "thrust_level"}
    (effect,) = [e for e in CATALOGUE[family[shape]].refinements(vehicle_of(fit)) if e.name == shape]
    starts = onset_starts(fit, effect.scan)
    assert 1 <= len(starts) <= 4
    assert min(abs(st[time_name] - when) for st in starts) <= 2.5, starts


def test_the_window_scan_starts_a_refit_at_both_edges_of_a_throttle_bucket():
    """A throttle bucket from the truth's own dynamics (15 % down over 22-40 s, 2 s linear ramps; another
    window than the study's case): the window's scan over pairs of onset times puts a start within 2.5 s of
    both edges (the ramps' midpoints, 23 and 39 s), with a throttle-*down* as its one-step size."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.score import onset_starts
    from rocketid.diagnostics.screen import vehicle_of

    spec = halcyon.build_model()
    hidden = {"throttle": {"depth": 0.15, "t_on": 22.0, "t_off": 40.0, "ramp": 2.0}}
    fit = ri.estimate(spec, _measurements(truth.measurements(run.TIMES, hidden, seed=6), spec))
    (window,) = [e for e in CATALOGUE["thrust_level"].refinements(vehicle_of(fit)) if e.name == "throttle_window"]
    starts = onset_starts(fit, window.scan)
    assert 1 <= len(starts) <= 4
    near = [st for st in starts if abs(st["t_win_on"] - 23.0) <= 2.5 and abs(st["t_win_off"] - 39.0) <= 2.5]
    assert near and near[0]["d_window"] > 0, starts


def test_a_short_deep_bucket_makes_the_thrust_family_a_contender_by_its_scan():
    """A short deep throttle bucket from the truth's own dynamics (30 % down over 35-41 s, 1.5 s ramps; the
    throttle checks' case, benchmarks/throttle_checks.py): the constant thrust error is significant but ranked
    out (confounded, far below the leader), while the window's scan peaks at the bucket, so the screen refits
    the thrust family and marks it for its located shapes."""
    from rocketid.diagnostics.api import _candidate_effects
    from rocketid.diagnostics.screen import screen

    spec = halcyon.build_model()
    hidden = {"throttle": {"depth": 0.3, "t_on": 35.0, "t_off": 41.0, "ramp": 1.5}}
    fit = ri.estimate(spec, _measurements(truth.measurements(run.TIMES, hidden, seed=23), spec))
    scr = screen(fit, _candidate_effects(None))
    (thrust,) = [c for c in scr.contenders if c.effect.name == "thrust_level"]
    assert thrust.located == "throttle_window" and thrust.why.startswith("its located shape"), thrust.why
    on, off = (float(v) for v in re.search(r"at ([0-9.]+)-([0-9.]+) ", thrust.why).groups())
    assert abs(on - 35.75) <= 2.5 and abs(off - 40.25) <= 2.5, thrust.why    # the ramps' midpoints


def test_clean_data_qualify_no_located_shape():
    """On clean truth data the screen refits no family for a located shape's scan."""
    from rocketid.diagnostics.api import _candidate_effects
    from rocketid.diagnostics.screen import screen

    spec = halcyon.build_model()
    for seed in (12, 13):
        fit = ri.estimate(spec, _measurements(truth.measurements(run.TIMES, {}, seed=seed), spec))
        scr = screen(fit, _candidate_effects(None))
        assert not [c.effect.name for c in scr.contenders if c.located], [c.why for c in scr.contenders]


def _measurements(table, spec) -> "ri.Measurements":
    """The truth's samples as rocketid measurements (the model's sigmas)."""
    return ri.Measurements(tuple(ri.Channel(c, np.asarray(table["t"], float), np.asarray(table[c], float))
                                 for c in ("x", "h", "v")))


@pytest.mark.slow
@pytest.mark.parametrize("name", list(C.CASES))
def test_blind_case(name):
    rec = run.collect(name, run.run_case(name))
    if name in KNOWN_FAILURES:
        if run.acceptable(rec):
            pytest.fail(f"{name} now meets the bar ({rec['outcome']}): remove it from KNOWN_FAILURES")
        pytest.xfail(KNOWN_FAILURES[name])
    assert run.acceptable(rec), rec
    assert not rec["outcome"].startswith("WRONG"), rec


def test_a_speed_sensor_lag_is_explained_by_that_channel_s_latency(tmp_path):
    """The blind ``v_lag`` case (the truth's speed sensor a first-order lag of 80 ms, written in
    tests/blind_study/truth.py as a filter, not as a delay): the catalogue's sensor shapes only approximate
    it (the first search ends ``bias_v_drift`` + ``time_offset_2`` at chi2/dof 1.132; since fa0cdf5 the second
    path's ``scale_v`` + ``bias_v`` reach 1.082, inside the band). Given the opt-in ``sensor_lag_effect("v")``
    beside the catalogue, the diagnosis explains it as that channel's latency, 80 ms."""
    from rocketid.diagnostics import CATALOGUE, diagnose, sensor_lag_effect

    text, effects, seed, _ = C.CASES["v_lag"]
    csv = tmp_path / "v_lag.csv"
    truth.write_csv(csv, truth.measurements(run.TIMES, effects, seed=seed))
    rep = diagnose(csv, str(HERE / "vehicles" / "halcyon.py"), workers=1, variant=False,
                   candidates=[*CATALOGUE.values(), sensor_lag_effect("v")])
    assert rep.final.verdict == "explained" and rep.final.effects == ("sensor_lag_v",), rep.final.explanation
    tau, se = rep.final.parameters["tau_v"]
    assert abs(tau - 0.080) < max(0.1 * 0.080, 3 * se), (tau, se)
