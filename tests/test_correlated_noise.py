"""Errors correlated in time (``rocketid.diagnostics.correlated``): found on the base fit's residuals, and
the channels thinned to the samples whose errors are independent before anything is judged.

The end-to-end checks use Halcyon-8, the blind study's vehicle (``tests/vehicles/halcyon.py``, declared
from the user documentation) flown by its own simulator (``tests/blind_study/truth.py``: Earth-centred
Cartesian flight, its own atmosphere, nothing shared with rocketid's equations), with the errors a
navigation filter leaves: white noise through a first-order filter (``scipy.signal.lfilter``), its
marginal standard deviation the sensor's stated sigma. The series checks hold the rule on white noise,
on first-order and moving-average errors, and on what it must leave alone (a smooth misfit, a stretch of
larger noise).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

HERE = Path(__file__).resolve().parent

import halcyon as V  # noqa: E402

import rocketid as ri  # noqa: E402
from rocketid.diagnostics import diagnose  # noqa: E402
from rocketid.data import difference_noise  # noqa: E402
from rocketid.diagnostics.api import base_fit, resolve_model  # noqa: E402
from rocketid.diagnostics.compare import compare  # noqa: E402
from rocketid.diagnostics.correlated import (DETECT, RESIDUAL, CorrelatedNoise, noise_correlation,  # noqa: E402
                                             thin_channel)
from rocketid.errors import SettingsError  # noqa: E402
from blind_study import truth  # noqa: E402

MODEL = str(HERE / "vehicles" / "halcyon.py")
TIMES = 0.1 * np.arange(1, 801)
RHO = 0.6          # a first-order filter of 0.2 s at 10 Hz


def _filtered(n: int, rho: float, rng) -> np.ndarray:
    """Unit-variance white noise through a first-order filter: errors correlated ``rho ** k`` at ``k`` samples."""
    return lfilter([math.sqrt(1.0 - rho ** 2)], [1.0, -rho], rng.standard_normal(n))


def _halcyon(effects: dict, seed: int, *, stated: bool = True, rho: float = RHO) -> ri.Measurements:
    out = truth.simulate(TIMES, effects)
    rng = np.random.default_rng(seed)
    return ri.Measurements(tuple(
        ri.Channel(c, TIMES, out[c] + V.SIGMA[c] * _filtered(TIMES.size, rho, rng), V.SIGMA[c] if stated else None)
        for c in ("x", "h", "v")))


# ---------------------------------------------------------------- the rule on series

def test_white_noise_is_never_called_correlated():
    rng = np.random.default_rng(11)
    for n, dt in ((6600, 0.01), (800, 0.1), (377, 0.1)):
        t = dt * np.arange(n)
        found = [noise_correlation("x", t, rng.standard_normal(n)) for _ in range(150)]
        assert not any(c.correlated for c in found), n
        assert all(c.stride == 1 and c.kept == n for c in found)


@pytest.mark.parametrize("rho", [0.3, 0.6, 0.9])
def test_first_order_errors_are_found_and_thinned_to_independent_samples(rho):
    rng = np.random.default_rng(int(100 * rho))
    n = 6600
    t = 0.01 * np.arange(n)
    e = _filtered(n, rho, rng)
    c = noise_correlation("v", t, e)
    assert c.correlated and c.settled
    assert abs(c.rho - rho) < 0.05
    assert rho ** c.stride <= 2 * RESIDUAL
    # what the one-sample differences see: (70 - 112 rho + 56 rho^2 - 16 rho^3 + 2 rho^4) / 70 of the variance
    seen = (70 - 112 * rho + 56 * rho ** 2 - 16 * rho ** 3 + 2 * rho ** 4) / 70
    assert abs(1.0 / c.ratio - seen) < 0.1 * seen + 0.02
    kept = e[::c.stride]
    assert abs(np.corrcoef(kept[:-1], kept[1:])[0, 1]) < 0.2
    assert c.kept == len(kept)


@pytest.mark.parametrize("rho", [0.6, 0.8])
def test_second_order_errors_are_found(rho):
    """A navigation filter's position: white noise through two first-order filters, whose scatter rises like the
    stride's cube at first."""
    rng = np.random.default_rng(int(10 * rho))
    t = 0.1 * np.arange(800)
    e = lfilter([1.0], [1.0, -rho], lfilter([1.0], [1.0, -rho], rng.standard_normal(t.size)))
    c = noise_correlation("h", t, e / e.std())
    assert c.correlated and c.stride >= 7


def test_a_motor_ripple_is_not_taken_for_filtered_errors():
    """A misfit of a second's period while the motor burns (a quarter of the flight), one sigma: its scatter rises
    only at longer strides and only where it acts."""
    rng = np.random.default_rng(4)
    t = 0.1 * np.arange(800)
    ripple = np.sin(2 * np.pi * t / 1.2) * ((t > 5) & (t < 25))
    assert not any(noise_correlation("v", t, ripple + rng.standard_normal(t.size)).correlated for _ in range(30))


def test_a_moving_average_is_thinned_past_its_length():
    rng = np.random.default_rng(5)
    n = 6600
    e = np.convolve(rng.standard_normal(n + 9), np.ones(10) / math.sqrt(10), "valid")
    c = noise_correlation("h", 0.01 * np.arange(n), e)
    assert c.correlated and c.stride >= 10


@pytest.mark.parametrize("shape", ["smooth misfit", "larger noise late", "quantized slow signal"])
def test_what_is_not_correlated_noise(shape):
    rng = np.random.default_rng(7)
    n = 6600
    t = 0.01 * np.arange(n)
    e = rng.standard_normal(n)
    if shape == "smooth misfit":       # a missing effect's residual, 5 sigma, three swings over the flight
        e = e + 5.0 * np.sin(2 * np.pi * t / (t[-1] / 3))
    elif shape == "larger noise late":  # engine vibration: white, four times larger after the middle
        e[n // 2:] *= 4.0
    else:                              # a fine step on a fast signal: rounding errors independent
        e = np.round((50.0 * t + e) / 0.1) * 0.1 - 50.0 * t
    assert not noise_correlation("x", t, e).correlated


def test_errors_correlated_longer_than_the_limit_are_said_to_be_so():
    rng = np.random.default_rng(3)
    n = 800
    t = 0.1 * np.arange(n)
    c = noise_correlation("x", t, _filtered(n, 0.97, rng))
    assert c.correlated and not c.settled
    note = CorrelatedNoise((c,)).note()
    assert c.stride == c.scatter[-1][0] and c.stride * 0.1 <= 2.0      # thinned at the largest stride tried
    assert "cannot be told from a missing effect" in note and f"x {c.kept} of 800" in note


def test_thinning_restarts_after_a_dropout_and_keeps_per_sample_sigmas():
    t = np.concatenate([0.1 * np.arange(100), 20.0 + 0.1 * np.arange(50)])
    sigma = np.linspace(1.0, 2.0, t.size)
    ch = ri.Channel("h", t, np.zeros(t.size), sigma)
    thin = thin_channel(ch, 7)
    assert list(thin.times[:3]) == pytest.approx([0.0, 0.7, 1.4])
    assert 20.0 in thin.times                       # the second run's first sample
    assert thin.sigma == pytest.approx(sigma[np.isin(t, thin.times)])


# ---------------------------------------------------------------- the diagnosis

@pytest.fixture(scope="module")
def clean_filtered():
    return _halcyon({}, seed=1)


def test_a_right_model_with_filtered_errors_is_left_alone(clean_filtered, tmp_path):
    rep = diagnose(clean_filtered, MODEL, workers=1, out=tmp_path / "d")
    assert rep.final.verdict == "nothing missing" and rep.final.effects == ()
    corr = rep.correlated_noise
    assert [c.channel for c in corr.correlated] == ["x", "h", "v"]
    assert all(abs(c.rho - RHO) < 0.1 and 4 <= c.stride <= 12 for c in corr.correlated)
    kept = {c.name: c.times.size for c in rep.fit.prepared.measurements.channels}
    assert kept == {c.channel: c.kept for c in corr.correlated} and all(k < 800 for k in kept.values())
    assert "errors correlated in time" in rep.verdict()[0].lower()
    saved = json.loads((tmp_path / "d" / "diagnosis.json").read_text())["correlated_noise"]
    assert saved["action"] == "thin" and {c["channel"]: c["kept"] for c in saved["channels"]} == kept


def test_on_every_sample_the_same_data_are_called_unexplained(clean_filtered):
    """What thinning prevents: with every sample kept, the right model's residuals are "not white"."""
    fit, _, _, _, corr = base_fit(resolve_model(MODEL)[0], clean_filtered, correlated_noise="keep")
    assert corr and fit.prepared.measurements.n_samples == 3 * 800
    assert not compare(fit).fits_to_noise
    rep = diagnose(clean_filtered, MODEL, workers=1, correlated_noise="keep")
    assert rep.final.verdict != "nothing missing"


def test_the_noise_from_the_data_is_the_errors_full_size():
    data = _halcyon({}, seed=3, stated=False)
    rep = diagnose(data, MODEL, sigma="estimate", workers=1)
    assert rep.final.verdict == "nothing missing"
    for c in ("x", "h", "v"):
        sigma, n = rep.noise_from_data[c]
        assert abs(sigma / V.SIGMA[c] - 1.0) < 0.25, (c, sigma)
        # every sample's differences see about half of it (sqrt of 0.27 at rho 0.6)
        assert difference_noise(data[c])[0] < 0.65 * V.SIGMA[c]


def test_a_thrust_shortfall_is_found_through_filtered_errors():
    rep = diagnose(_halcyon({"thrust_eps": -0.025}, seed=2), MODEL, workers=1)
    assert rep.correlated_noise
    assert rep.final.effects == ("thrust_level",) and rep.final.verdict == "explained"
    eps, std = rep.final.parameters["eps_thrust"]
    assert abs(eps + 0.025) < max(3 * std, 0.001)


def test_a_bad_setting_is_refused(clean_filtered):
    with pytest.raises(SettingsError, match="correlated_noise must be one of thin, keep"):
        diagnose(clean_filtered, MODEL, correlated_noise="drop")


def test_the_command_line_takes_the_setting(clean_filtered, tmp_path):
    from click.testing import CliRunner
    from rocketid.cli import main
    csv = tmp_path / "flight.csv"
    np.savetxt(csv, np.column_stack([TIMES] + [clean_filtered[c].values for c in ("x", "h", "v")]), delimiter=",",
               header="t,x,h,v", comments="")
    out = CliRunner().invoke(main, ["diagnose", str(csv), "--model", MODEL, "--out", str(tmp_path / "r"),
                                    "--workers", "1", "--correlated-noise", "keep", "--max-effects", "1"])
    assert out.exit_code == 0, out.output
    saved = json.loads((tmp_path / "r" / "diagnosis.json").read_text())["correlated_noise"]
    assert saved["action"] == "keep" and all(c["correlated"] for c in saved["channels"])
    assert "--correlated-noise keep" in out.output


def test_detect_is_well_above_the_white_noise_scatter():
    """The detection margin against the measured scatter of the level on white noise."""
    rng = np.random.default_rng(2)
    t = 0.01 * np.arange(6600)
    levels = [noise_correlation("x", t, rng.standard_normal(t.size)).ratio for _ in range(100)]
    err = math.sqrt(8 / 6596)
    assert max(levels) < 1 + DETECT * err


def test_the_fit_command_warns_that_white_noise_standard_errors_are_too_small(clean_filtered, tmp_path):
    from click.testing import CliRunner
    from rocketid.cli import main
    csv = tmp_path / "flight.csv"
    np.savetxt(csv, np.column_stack([TIMES] + [clean_filtered[c].values for c in ("x", "h", "v")]), delimiter=",",
               header="t,x,h,v", comments="")
    white = CliRunner().invoke(main, ["estimate", str(csv), "--model", MODEL, "--out", str(tmp_path / "w.json")])
    assert white.exit_code == 0, white.output
    assert "the errors look correlated in time" in white.output and "--errors coloured" in white.output
    saved = json.loads((tmp_path / "w.json").read_text())["correlated_noise"]
    assert [c["channel"] for c in saved["channels"] if c["correlated"]] == ["x", "h", "v"]
    coloured = CliRunner().invoke(main, ["estimate", str(csv), "--model", MODEL, "--errors", "coloured"])
    assert coloured.exit_code == 0, coloured.output
    assert "the errors look correlated in time" not in coloured.output


def test_several_flights_each_thinned_as_its_diagnosis_thinned_it(clean_filtered):
    """Two flights, one with filtered errors and one with white: each diagnosis measures its own, and the joint
    fit uses each flight's data as its diagnosis did (the filtered flight thinned channel by channel)."""
    from rocketid.commands.diagnose_flights import diagnose_flights
    out = truth.simulate(TIMES, {})
    rng = np.random.default_rng(21)
    white = ri.Measurements(tuple(ri.Channel(c, TIMES, out[c] + V.SIGMA[c] * rng.standard_normal(TIMES.size),
                                             V.SIGMA[c]) for c in ("x", "h", "v")))
    res = diagnose_flights([clean_filtered, white], ["filtered", "white"], resolve_model(MODEL)[0], confirm_top=0,
                           workers=1)
    first, second = res.reports
    assert first.correlated_noise and not second.correlated_noise
    assert res.joint is not None and res.joint.success
    used = [{c.name: c.times.size for c in f.prepared.measurements.channels} for f in res.joint.flights]
    assert used[0] == {c.channel: c.kept for c in first.correlated_noise.correlated}
    assert used[1] == {"x": 800, "h": 800, "v": 800}
