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

import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
for extra in (HERE, HERE / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import halcyon  # noqa: E402

import rocketid as ri  # noqa: E402
from rocketid.estimability import uncertainty  # noqa: E402

from blind_study import cases as C  # noqa: E402
from blind_study import run, truth  # noqa: E402

#: Cases measured not to meet the bar, with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "misalign_late": "cecf6a5: a 0.2 deg misalignment switched on at 20 s: the catalogue's wind reaches the noise "
                     "(chi2/dof 0.962, CL_alpha 2.38 for 3.0) but predicts the held-out flight worse than the base "
                     "model (x 111 against 13.3 m): partly explained, a wrong family (it was called explained before "
                     "a0926ee)",
    "x-misalign_late-s2": "cecf6a5: the same on seed 207: wind_pl_6 (W_5 -17.8 m/s) reaches the noise with CL_alpha "
                          "moved, verdict explained; the constant misalignment stops just above the band, no catalogue "
                          "shape has an onset time, and the hold-out is not decisive (x 13.0 -> 9.8 m, h 12.5 -> 18.6 m)",
    "x-misalign_late-neg": "cecf6a5: the same with -0.2 deg: the catalogue's wind (about 0.6 m/s) with CL_alpha 3.76 "
                           "for 3.0, verdict explained",
    "altimeter_scale": "cecf6a5: h read 0.4 % high (no altitude scale factor in the catalogue): bias_h_drift beside "
                       "a wrong speed scale factor and a half-rate Earth rotation, partly explained",
    "dropped_mass": "cecf6a5: 150 kg released at 55 s (no catalogue shape): a 9-knot thrust profile reaches the "
                    "noise with CD_0 at its lower bound: partly explained, a wrong family",
    "throttle_bucket": "cecf6a5: thrust and mass flow 20 % down at 30-45 s are absorbed into the CD(M) knots near "
                       "Mach 1 (CD_3 1.28 for 0.53); wind_pl_6 + drag_mach_7 + earth_rotation end at chi2/dof 1.5, "
                       "partly explained, no thrust term",
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
