"""``rocketid diagnose`` on telemetry as it really comes: unknown noise, multi-rate channels with gaps, a
record that starts in flight.

Corvid-L (``tests/vehicles/corvid.py``) is declared from the user documentation: a guided liquid first
stage lifting off from rest at Andoya (69.29 N, azimuth 345 deg), 950 kN and 340 kg/s at full throttle
with a commanded throttle schedule (a max-q bucket at 0.72, an acceleration limit at 0.8), a stored pitch
program with lift (``alpha = phi - theta``, ``CL_alpha alpha``), CD as a Mach table. Its telemetry is
acquired from T+12 s: speed 10 Hz, altitude 2 Hz, downrange 1 Hz with a radar hand-over gap, drop-outs,
quantized words, no stated noise; the diagnosis runs with ``--sigma estimate --window 12:``. The truth
(``tests/telemetry_study/truth.py``) flies Cartesian position and velocity about the Earth's centre with
vector forces and its own 1976 atmosphere.

The normal suite checks the instruments (truth against ``rocketid.simulate``, the atmosphere, the flight
the docstring states, the telemetry's shape, each effect's size and visibility, the scoring rules). The
diagnoses are ``slow``: ``pytest -m slow tests/test_telemetry_study.py``; the whole study with its table
is ``python tests/telemetry_study/run.py --json telemetry.json``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest


import corvid as V

import rocketid as ri
from study_harness import Case
from telemetry_study import truth
from telemetry_study.run import STUDY
from telemetry_study.cases import (A_EXIT, ALL, BIAS_V, BY_NAME, DM0, EPS_THRUST, JET, K_H, MEASURED_2J,
                                   RADAR_OFFSET, TAU, VISIBLE_2J, Hidden)

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "light-load": "588676e: start_mass (dm_start -492 kg for -500) and thrust_level (eps 0.0103) reach the noise "
                  "within BIC 10 and the hold-out (fitted on 12-72 s) predicts neither (mean squared error / "
                  "sigma^2 23.8 and 69.2): the tie named -- x, h and v see thrust and mass only through their "
                  "ratio; headed 'not explained by the catalogue' until a first-step tie became 'partly explained' "
                  "(2026-11-28, the same case re-run: the same tie, nothing added)",
    "filtered-hot-engine": "2c5ac39: the speed's filtered errors are found and thinned (rho 0.82, every 14th sample, its "
                           "noise 0.240 for 0.25), but the altitude's (rho 0.37 at 2 Hz) are hidden under the thrust "
                           "error's misfit on the base fit: its noise from the data is 4.59 m for 6, and thrust_level "
                           "(eps 0.042 +- 0.008 for 0.025) ends at chi2/dof 1.61 above the band, 'partly explained'",
}

WINDOW = (V.T_ACQUIRE, V.TF)


@pytest.fixture(scope="module")
def spec():
    return V.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), V.sample_times())


def test_truth_reproduces_the_vehicle_model(spec, clean_outputs):
    """Cartesian position and velocity with vector forces (truth) against speed and path angle (rocketid's
    model, ``simulate``), from lift-off: < 1 mm and < 1 mm/s at every telemetry time (measured 2e-6 m),
    far below the telemetry's noise (20 m, 6 m, 0.25 m/s)."""
    t = V.sample_times()
    model = ri.simulate(spec, V.truth(spec), t).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < 1e-3, name


def test_the_truth_atmosphere_is_the_models(spec):
    """The truth's own hydrostatic 1976 layers against the model's density and speed of sound along the
    flight (to 1e-6), and the standard's published values."""
    t = np.arange(0.0, V.TF + 1e-9, 1.0)
    tr = ri.simulate(spec, V.truth(spec), t)
    air = truth.Air()
    for h, rho, a in zip(tr.states[:, 1], tr.value("rho"), tr.value("a_sound")):
        _, _, rho_t, a_t = air.at(float(h))
        assert abs(rho_t / rho - 1) < 1e-6 and abs(a_t / a - 1) < 1e-6, h
    for z, T, p, rho in ((0.0, 288.150, 101_325.0, 1.2250), (10_000.0, 223.252, 26_499.9, 0.41351),
                         (20_000.0, 216.650, 5_529.3, 0.088910), (30_000.0, 226.509, 1_197.0, 0.018410)):
        Tt, pt, rt, _ = air.at(z)
        assert abs(Tt - T) < 2e-3 and abs(pt / p - 1) < 5e-5 and abs(rt / rho - 1) < 5e-5, z


def test_the_flight_is_the_stated_one(spec):
    """Mach 1 at 42 s, max q 35.7 kPa at 45 s in the bucket (its ramp-down), the window's start at Mach 0.21 (the
    table's first knot), the peak Mach 3.65 above the last knot; 28.9 km, 28.4 km downrange, 1098 m/s and
    29.2 deg at 100 s; 30.7 t left."""
    t = np.arange(0.0, V.TF + 1e-9, 0.05)
    tr = ri.simulate(spec, V.truth(spec), t)
    x, h, v, theta = tr.states.T
    mach, q = tr.value("mach"), tr.value("qbar")
    assert 41.5 < t[np.argmax(mach > 1.0)] < 42.5
    assert 35.0e3 < q.max() < 36.5e3 and V.THROTTLE_TIMES[0] < t[q.argmax()] < V.THROTTLE_TIMES[3]
    assert abs(mach[t == V.T_ACQUIRE][0] - V.CD_KNOTS[0]) < 0.01
    assert V.CD_KNOTS[-1] < mach.max() < 3.7
    assert 28.5e3 < h[-1] < 29.3e3 and 28.0e3 < x[-1] < 28.8e3 and 1090 < v[-1] < 1105
    assert 28.5 < math.degrees(theta[-1]) < 30.0 and abs(tr.value("mass")[-1] - 30_720.0) < 1.0
    alpha = np.degrees(tr.value("alpha"))[t >= V.T_ACQUIRE]
    assert -0.5 < alpha.min() and alpha.max() < 3.0               # near zero through max q, +2.5 deg lofting


def test_the_telemetry_comes_as_stated(tmp_path, monkeypatch):
    """The harness writes one multi-rate CSV (empty cells where a channel has no sample): speed 10 Hz,
    altitude 2 Hz, downrange 1 Hz from T+12 s, the radar's gap and the loss of signal, about 3 % of frames
    dropped, quantized words, and no sigma (the diagnosis estimates it)."""
    monkeypatch.setenv("ROCKETID_TELEMETRY_DIR", str(tmp_path))
    case = BY_NAME["clean-900"]
    path = STUDY.make_data(case)
    assert path.parent == tmp_path
    lines = path.read_text().splitlines()
    assert lines[0] == "t,x,h,v" and any(",," in line for line in lines[1:])
    data = ri.read_csv(path, ("x", "h", "v"))
    ch = {c.name: c for c in data.channels}
    nominal = V.channel_times()
    for name, step in V.RATE.items():
        c = ch[name]
        assert c.sigma is None
        assert c.times[0] >= V.T_ACQUIRE and c.times[-1] <= V.TF
        lost = 10 if name == "x" else 0                             # the radar's hand-over gap
        assert 0.90 * (nominal[name].size - lost) - 3 < c.times.size < 0.99 * nominal[name].size, name
        assert np.allclose(np.diff(c.times) / step, np.round(np.diff(c.times) / step), atol=1e-6)
        assert not np.any((c.times > truth.LOS[0]) & (c.times < truth.LOS[1])), name
        q = V.QUANTUM[name]
        assert np.allclose(c.values / q, np.round(c.values / q), atol=1e-6), name
    assert not np.any((ch["x"].times > truth.RADAR_GAP[0]) & (ch["x"].times < truth.RADAR_GAP[1]))
    exact = truth.exact_outputs(Hidden(), None, per_channel={n: ch[n].times for n in ch})
    for name in ("x", "h", "v"):
        resid = ch[name].values - exact[name]
        assert abs(np.std(resid) / math.hypot(V.SIGMA[name], V.QUANTUM[name] / math.sqrt(12)) - 1) < 0.2, name


def test_vehicle_fits_clean_telemetry_with_the_noise_estimated(spec):
    """The user's fit, as the docs describe it: the window from T+12 s (the states there estimated), every
    channel's sigma estimated; the sigmas come out at the truth's (with the quantization) and every
    coefficient within 4 standard errors of the truth."""
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(spec, data, sigma="estimate", window=WINDOW)
    assert fit.success, fit.message
    for name in ("x", "h", "v"):
        expected = math.hypot(V.SIGMA[name], V.QUANTUM[name] / math.sqrt(12))
        assert abs(fit.sigma[name] / expected - 1) < 0.15, (name, fit.sigma[name], expected)
    se = uncertainty(fit).standard_errors
    names = fit.spec.parameter_names
    true = V.truth(spec)
    z = {n: (p - true[n]) / s for n, p, s in zip(names, fit.p, se) if n in true}
    assert set(z) == set(true) and max(abs(v) for v in z.values()) < 4, z


@pytest.mark.parametrize("name", sorted(MEASURED_2J))
def test_visibility(spec, name):
    """Each case's ``visible`` is what the base model's fit over the window to its noise-free telemetry (the
    truth's sigmas) leaves: 2J >= 25 visible (measured values in ``cases.MEASURED_2J``, within 20 %)."""
    case = BY_NAME[name]
    times = truth.telemetry_times(case.seed)
    exact = truth.exact_outputs(case.hidden, None, per_channel=times)
    data = ri.Measurements(tuple(ri.Channel(n, times[n], exact[n], V.SIGMA[n]) for n in ("x", "h", "v")))
    fit = ri.estimate(spec, data, window=WINDOW)
    two_j = 2.0 * fit.data_objective
    assert (two_j >= VISIBLE_2J) == bool(case.visible), (name, two_j)
    assert two_j < 1.0 if MEASURED_2J[name] < 1.0 else abs(two_j / MEASURED_2J[name] - 1) < 0.2, (name, two_j)


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change over 12-100 s
    (Hidden(eps_thrust=EPS_THRUST), "v", 40.0, 50.0),              # 44.8 m/s
    (Hidden(bucket_level=0.67), "v", 25.0, 31.0),                  # 28.1 m/s
    (Hidden(A_e=A_EXIT), "v", 75.0, 95.0),                         # 85.2 m/s
    (Hidden(wind=JET), "v", 7.0, 9.5),                              # 8.15 m/s
    (Hidden(dT=12.0), "h", 14.0, 20.0),                             # 16.9 m
    (Hidden(bias_v=BIAS_V), "v", 0.999, 1.001),                    # 1 m/s
    (Hidden(scale_h=K_H), "h", 110.0, 120.0),                      # 115.6 m
    (Hidden(tau=TAU), "v", 1.8, 2.4),                               # 2.10 m/s (0.1 s of 21 m/s^2)
    (Hidden(dm0=DM0), "v", 18.0, 23.0),                             # 20.7 m/s
    (Hidden(gravity=truth.SITE_GRAVITY), "v", 1.0, 1.4),           # 1.21 m/s
    (Hidden(radar_offset=RADAR_OFFSET), "x", 1400.0, 1500.0),       # 1489 m at 12.1 s
])
def test_each_hidden_effect_changes_the_telemetry(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount (largest change in range) and by many
    sigma over the record (root sum of squares of the changes in sigma over the channels' own times)."""
    moved = truth.exact_outputs(hidden, V.sample_times())
    change = float(np.max(np.abs(moved[channel] - clean_outputs[channel])))
    assert low < change < high, change
    times = V.channel_times()
    clean = truth.exact_outputs(Hidden(), None, per_channel=times)
    shifted = truth.exact_outputs(hidden, None, per_channel=times)
    significance = math.sqrt(sum(float(np.sum(((shifted[n] - clean[n]) / V.SIGMA[n]) ** 2)) for n in times))
    assert significance > 50.0, significance


def test_the_bucket_and_the_nozzle_are_the_stated_ones():
    """The deep bucket is 0.67 where 0.72 was commanded, ramps as commanded; the nozzle term is 0 at sea
    level at full throttle, +7.6 % of the thrust in vacuum, and in the bucket 20 kN below the catalogue's
    throttle-independent ``A_e (p0 - p_a)``."""
    deep = truth.Flight(Hidden(bucket_level=0.67))
    assert deep.throttle(50.0) == 0.67 and deep.throttle(30.0) == 1.0 and abs(deep.throttle(44.0) - 0.835) < 1e-12
    nozzle = truth.Flight(Hidden(A_e=A_EXIT))
    p0 = truth.SEA_LEVEL_PRESSURE
    assert abs(nozzle.thrust(10.0, p0) - V.THRUST_FULL) < 1e-6
    assert abs(nozzle.thrust(95.0, 0.0) - 0.8 * V.THRUST_FULL - A_EXIT * 0.8 * p0) < 1e-6
    assert abs(A_EXIT * p0 / V.THRUST_FULL - 0.0757) < 1e-3
    p_a = truth.Air().at(10_000.0)[1]
    catalogue = 0.72 * V.THRUST_FULL + A_EXIT * (p0 - p_a)
    assert 19.5e3 < catalogue - nozzle.thrust(50.0, p_a) < 20.5e3


def test_the_cases_are_consistent():
    """Names and seeds unique, every needed family a right one, pairs with one set per effect, five clean
    seeds, the out-of-catalogue cases with nothing right, ``visible`` from the measured 2J."""
    assert len(BY_NAME) == len(ALL) == 22 and len({c.seed for c in ALL}) == len(ALL)
    for case in ALL:
        assert case.needed <= case.right, case.name
        assert all(group <= case.right for group in case.needed_each), case.name
        assert ("+" in case.name) == bool(case.needed_each), case.name
        if case.right:
            assert case.needed and case.visible is not None, case.name
        if case.name in MEASURED_2J:
            assert case.visible == (MEASURED_2J[case.name] >= VISIBLE_2J), case.name
    assert sum(c.name.startswith("clean-") for c in ALL) == 5
    assert {c.name for c in ALL if c.out_of_catalogue} == {"site-gravity", "radar-geometry"}
    assert all(not c.right for c in ALL if c.out_of_catalogue)
    assert set(STUDY.coefficients) == {f"CD_{j}" for j in range(len(V.CD_KNOTS))} | {"CL_alpha"}


def test_the_harness_runs_the_regime(monkeypatch, tmp_path):
    """The diagnosis command carries ``--sigma estimate --window 12:``; the other studies' command is
    unchanged (``extra_args`` empty by default)."""
    import dataclasses
    import subprocess

    from sounding_study import run as sounding
    seen = []

    def fake(command, **kwargs):
        seen.append(command)
        return subprocess.CompletedProcess(command, 2, "", "no")
    monkeypatch.setattr(subprocess, "run", fake)
    monkeypatch.setenv("ROCKETID_TELEMETRY_DIR", str(tmp_path))
    monkeypatch.setenv("ROCKETID_SOUNDING_DIR", str(tmp_path))
    record = STUDY.diagnose_cli(BY_NAME["clean-900"])
    assert seen[-1][-4:] == ["--sigma", "estimate", "--window", "12:"]
    assert record["command"].endswith("--workers 1 --sigma estimate --window 12:")
    assert sounding.STUDY.extra_args == ()
    plain = dataclasses.replace(STUDY, extra_args=())
    plain.diagnose_cli(BY_NAME["clean-900"])
    assert seen[-1][-2:] == ["--workers", "1"]


def test_classification_rules():
    """The outcome classes with ``visible``: a visible effect must be found; an invisible one may go unfound;
    a located throttle shape is the thrust profile; a mass error for a time-tag delay is wrong."""
    final = {"effects": ["throttle_window"], "verdict": "explained", "parameters": {}}
    bucket = BY_NAME["deep-bucket"]
    assert STUDY.classify(bucket, {"final": final}) == "right & explained"
    assert STUDY.classify(bucket, {"final": {**final, "effects": ["thrust_level"]}}) == "right but partly"
    assert STUDY.classify(bucket, {"final": {**final, "effects": ["burn_rate"]}}) == "WRONG called explained"
    nothing = {"final": {**final, "effects": []}, "base_chi2": 1.001, "band": 1.05}
    assert not STUDY.acceptable(bucket, nothing)                      # visible: nothing found fails
    assert STUDY.acceptable(BY_NAME["hot-day"], nothing)              # absorbed by the drag table
    delay = BY_NAME["frame-delay"]
    assert STUDY.classify(delay, {"final": {**final, "effects": ["start_mass"]}}) == "WRONG called explained"
    assert STUDY.classify(delay, {"final": {**final, "effects": ["time_offset"]}}) == "right & explained"
    pair = BY_NAME["deep-bucket+v-bias"]
    assert STUDY.classify(pair, {"final": {**final, "effects": ["throttle_window"]}}) == "right but partly"
    assert STUDY.classify(pair, {"final": {**final, "effects": ["throttle_window", "bias_v"]}}) == "right & explained"
    hot = BY_NAME["hot-engine+hot-day"]
    assert STUDY.classify(hot, {"final": {**final, "effects": ["thrust_level"]}}) == "right & explained"
    assert STUDY.classify(hot, {"final": {**final, "effects": ["thrust_level", "temperature"]}}) == "right & explained"
    radar = BY_NAME["radar-geometry"]
    assert STUDY.acceptable(radar, {"final": {**final, "effects": ["bias_x"], "verdict": "partly explained"}})
    assert not STUDY.acceptable(radar, {"final": {**final, "effects": ["bias_x"]}})
    assert STUDY.acceptable(BY_NAME["vibration-noise"], nothing)
    assert not STUDY.acceptable(BY_NAME["vibration-noise"], {"final": {**final, "effects": ["scale_v"],
                                                                       "verdict": "partly explained"}})
    legacy = Case("x", Hidden(), 0, "x", right=frozenset({"wind"}), needed=frozenset({"wind"}))
    assert legacy.visible is None and STUDY.acceptable(legacy, nothing)        # the other studies' rule
    assert not STUDY.acceptable(legacy, {**nothing, "base_chi2": 1.3})


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_telemetry_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose --sigma estimate --window 12:`` (CLI) on the case: clean data add nothing, a
    visible effect is found and explained, an invisible one may go unfound, an out-of-catalogue one is not
    called explained, and a wrong family is never reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)
