"""The worked real-data example (docs/real-telemetry.md): Falcon 9 first-stage broadcast telemetry.

From a base model without a throttle schedule, the diagnosis must locate the failure in the
broadcast's throttle-down window (the events file is the answer key, never an input) and name a
thrust shortfall there; with the throttle effect added and the noise estimated, separately and
jointly: the altitude's estimated sigma is at the reading noise, the speed is at the reading
noise through the throttle-down and, after 90 s, as close as a model-free smooth curve gets --
but not at the reading noise (the estimated speed sigma is above it: a known failure, asserted
so that a change shows). Marked slow (a few minutes on 2 busy cores):
``pytest -m slow tests/test_falcon9.py``. Quick checks of the shipped data run always.
"""

from __future__ import annotations

import numpy as np
import pytest

import rocketid as ri
from rocketid.diagnostics import rank_candidates, throttle_effect, with_effects
from rocketid.diagnostics.locate import locate
from rocketid.examples.falcon9 import (FLIGHTS, LOAD_LIMIT, falcon9_data_path, falcon9_events, falcon9_measurements,
                                       falcon9_model, reading_noise, smooth_residuals)
from rocketid.joint import Flight, joint_estimate

CANDIDATES = ["thrust_level", "transonic_drag", "bias_v", "bias_h", "back_pressure"]


def test_shipped_data_are_the_credited_files():
    readme = (falcon9_data_path("CRS-11").parent / "README.md").read_text()
    assert "shahar603/Telemetry-Data" in readme and "Unlicense" in readme
    for flight in FLIGHTS:
        data = falcon9_measurements(flight, 20.0, 140.0)
        assert data.names == ("h", "v") and data["v"].times.size > 3000
        ev = falcon9_events(flight)
        assert ev["throttle_down_start"] < ev["throttle_down_end"] < ev["meco"]
        noise = reading_noise(data)
        # the reading noise is at least the quantization (100 m / sqrt 12, 0.278 m/s / sqrt 12)
        assert 25.0 < noise["h"] < 40.0 and 0.08 < noise["v"] < 0.4


def _span(findings, channel="v"):
    """The two largest drifts of ``channel`` in time order, and the time where their sign changes."""
    v = [f for f in findings if f.channel == channel][:2]
    v.sort(key=lambda f: f.t_start)
    return v


@pytest.mark.slow
@pytest.mark.parametrize("flight", list(FLIGHTS))
def test_diagnosis_finds_the_throttle_down_and_the_throttle_closes_it(flight):
    data = falcon9_measurements(flight)
    events = falcon9_events(flight)            # the answer key
    base = falcon9_model(data)
    fit0 = ri.estimate(base, data, options={"max_iter": 500})
    assert fit0.success and fit0.chi2_per_dof > 100
    loc = locate(fit0)
    first, second = _span(loc.findings)
    # the speed residual (model - measured) turns from too slow to too fast: the model keeps full
    # thrust where the vehicle throttled; the turn lies inside the broadcast's throttle-down window
    assert first.sign < 0 < second.sign
    turn = 0.5 * (first.t_end + second.t_start)
    assert events["throttle_down_start"] <= turn <= events["throttle_down_end"]
    # the score test names a throttle (thrust and mass flow down) over the flagged span first
    lo, hi = 5.0 * np.floor(first.t_start / 5.0), 5.0 * np.ceil(second.t_end / 5.0)
    knots = np.arange(lo, min(hi, base.tf - 10.0) + 1e-9, 5.0)
    ranking = rank_candidates(fit0, CANDIDATES + [throttle_effect(knots)])
    assert ranking.candidates[0].name == "throttle"
    # refit with the throttle: a shortfall (d > 0) of 10-35 % inside the broadcast's window
    # refined shape for the refit: knots every 2.5 s over the same span (the ranking's 5 s knots
    # name the effect; the steps of a real throttle need the finer ones)
    knots = np.arange(knots[0], knots[-1] + 1e-9, 2.5)
    spec = with_effects(base, [throttle_effect(knots)])
    fit = ri.estimate(spec, data, options={"max_iter": 500})
    assert fit.success
    d = {t: fit.value(f"d_throttle_{j}") for j, t in enumerate(knots) if 0 < j < len(knots) - 1}
    inside = [v for t, v in d.items() if events["throttle_down_start"] + 5 <= t <= events["throttle_down_end"] - 5]
    assert inside and 0.10 < np.mean(inside) < 0.35
    assert fit.rms["v"] < fit0.rms["v"] / 10
    # where the throttle acts (up to the end of the window) the speed error is at the reading noise;
    # after 110 s it is not (a known failure of this model, docs/real-telemetry.md)
    _at_the_noise_as_the_page_says(fit, data, events)
    # the noise estimated with the parameters: the altitude at its reading noise, the speed not
    fit_s = ri.estimate(spec, data, sigma="estimate", warm_start=fit, options={"max_iter": 500})
    assert fit_s.success and set(fit_s.sigma_estimated) == {"h", "v"}
    _estimated_sigmas_as_the_page_says(fit_s.sigma, data)
    _at_the_noise_as_the_page_says(fit_s, data, events)
    _errors_last_as_the_page_says(fit_s, fit, data)


def _acf(r, lag):
    r = np.asarray(r, float) - np.mean(r)
    return float(np.dot(r[:-lag], r[lag:]) / np.dot(r, r))


def _errors_last_as_the_page_says(fit_s, fit, data):
    """About a continuous curve (knots every 5 s) the speed's errors are correlated over half a second
    (model-free), the model's speed residual is no larger than the curve's, and the coloured-residual
    standard errors of the thrust and mass-flow scales are finite and below their priors' 0.03."""
    from rocketid.estimability import uncertainty
    curve = smooth_residuals(data, 5.0)["v"]
    assert _acf(curve, 15) > 0.3
    assert fit_s.rms["v"] <= np.sqrt(np.mean(curve ** 2))
    col = uncertainty(fit, coloured=True)
    se = dict(zip(col.parameter_names, col.standard_errors))
    assert 0 < se["k_P"] < 0.03 and 0 < se["k_mdot"] < 0.03


def _rms(r, k):
    return float(np.sqrt(np.mean(r[k] ** 2)))


def _at_the_noise_as_the_page_says(fit, data, events):
    """Through the throttle-down the speed is at the reading noise; after 90 s it is as close as a
    smooth curve with knots every 5 s gets (within 25 %), but not at the reading noise."""
    noise = reading_noise(data)
    r, t = fit.residuals["v"], data["v"].times
    assert _rms(r, t <= events["throttle_down_end"]) < 1.5 * noise["v"]
    late = t >= 90.0
    assert _rms(r, late) < 1.25 * _rms(smooth_residuals(data, 5.0)["v"], late)
    assert _rms(r, t >= 110.0) > 1.5 * noise["v"]


def _estimated_sigmas_as_the_page_says(sigma, data):
    """The altitude's estimated sigma within 30 % of its reading noise; the speed's at least 20 %
    above it (a model error or reading errors the model cannot follow, not white noise)."""
    noise = reading_noise(data)
    assert noise["h"] <= sigma["h"] * 1.05 and sigma["h"] < 1.3 * noise["h"]
    assert sigma["v"] > 1.2 * noise["v"]


def _throttle_knots(base, data):
    """Throttle knots every 2.5 s over the span the base fit's two largest speed drifts cover (as the page)."""
    fit0 = ri.estimate(base, data, options={"max_iter": 500})
    first, second = _span(locate(fit0).findings)
    lo, hi = 5.0 * np.floor(first.t_start / 5.0), 5.0 * np.ceil(second.t_end / 5.0)
    return np.arange(lo, min(hi, base.tf - 10.0) + 1e-9, 2.5)


@pytest.mark.slow
def test_the_late_altitude_misfit_of_crs12_is_the_attitude_bound():
    """CRS-12 with the throttle: under the shipped +-3 deg attitude bound the altitude after 110 s is far
    above its reading noise and the drag at Mach 2.5 sits at its upper bound (the fit bends the path with
    drag because the attitude cannot); with a load-limited attitude (``LOAD_LIMIT``: 2.5 deg at 30 kPa, at most
    15 deg in thin air) the altitude reaches its reading noise there, the speed is no worse, and every drag
    knot is plausible. Measured: 47.0 -> 31.5 m against 29.3 m; CD 0.22-1.50 -> 0.25-0.61."""
    data = falcon9_measurements("CRS-12")
    noise = reading_noise(data)
    shipped = falcon9_model(data)
    knots = _throttle_knots(shipped, data)
    fits = {}
    for label, base in (("shipped", shipped),
                        ("limited", falcon9_model(data, **LOAD_LIMIT))):
        fits[label] = ri.estimate(with_effects(base, [throttle_effect(knots)]), data, options={"max_iter": 500})
        assert fits[label].success, label
    late = data["h"].times >= 110.0
    h_late = {k: _rms(f.residuals["h"], late) for k, f in fits.items()}
    assert h_late["shipped"] > 1.4 * noise["h"] and h_late["limited"] < 1.15 * noise["h"], h_late
    v_late = data["v"].times >= 110.0
    assert _rms(fits["limited"].residuals["v"], v_late) <= 1.02 * _rms(fits["shipped"].residuals["v"], v_late)
    assert ("CD_4", "upper") in [(str(s), side) for s, side in fits["shipped"].active_bounds()]
    assert all(0.15 < fits["limited"].value(f"CD_{j}") < 1.0 for j in range(6))


@pytest.mark.slow
def test_both_flights_jointly_with_the_noise_estimated():
    """The two flights together: drag, thrust and mass-flow scales shared, each flight its own
    attitude, throttle (knots from its own diagnosis), lift-off mass and start states."""
    flights, keys = [], {}
    for label in FLIGHTS:
        data = falcon9_measurements(label)
        base = falcon9_model(data)
        flights.append(Flight(label, with_effects(base, [throttle_effect(_throttle_knots(base, data))]), data))
        keys[label] = falcon9_events(label)
    per = sorted({n for fl in flights for n in fl.spec.parameter_names
                  if n.startswith(("alpha", "d_throttle")) or n == "dm0"})
    joint = joint_estimate(flights, per_flight=per, sigma="estimate", options={"max_iter": 500})
    assert joint.success
    assert set(joint.layout.shared) == {"k_P", "k_mdot", *(f"CD_{j}" for j in range(6))}
    for fl, r in zip(flights, joint.flights):
        _estimated_sigmas_as_the_page_says(joint.sigma[fl.label], fl.data)
        _at_the_noise_as_the_page_says(r, fl.data, keys[fl.label])
    # with the noise estimated the shared drag stays plausible: no knot at a bound
    cd = [joint.theta[joint.layout.names.index(f"CD_{j}")] for j in range(6)]
    assert all(0.15 < c < 1.0 for c in cd)
    est = joint.estimability()
    assert np.all(est.eigenvalues > 0)
    # the subsonic drag is known from the priors, not from the data
    sub = [k for k in range(est.eigenvalues.size) if est.V[est.names.index("CD_0"), k] ** 2 > 0.5]
    assert sub and all(est.shares["prior"][k] > 0.8 for k in sub)
