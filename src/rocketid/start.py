"""Starting points that follow the data, flight windows, and sanity checks of a start and a fit.

In the simultaneous approach every node state is a variable, so the measured channels can
initialize the collocation states directly instead of a simulation at the guess:

* a state that an output measures directly (``m.output("h", h)``) takes the channel's
  values, smoothed by a local quadratic fit (window ``half_width`` either side) and read at
  the nodes;
* the flight-path angle (role ``flight_path_angle``) follows from the kinematic relations
  ``tan(theta) = (dh/dt) / (dx/dt)`` when downrange and altitude are measured, else
  ``sin(theta) = (dh/dt) / v`` from altitude and speed;
* the downrange (role ``downrange``), when not measured, is ``integral v cos(theta) dt``;
* any other state takes the simulation at the guess where it is finite, else its
  initial value.

:func:`start_states` uses the simulation at the guess when it is close to the data, and the
data otherwise; :func:`start_checks` and :func:`result_checks` say in the user's terms what
is wrong with a start trajectory or a result (the vehicle descends where the data climb, the
flight path turns through more than 90 degrees, every parameter at a bound, chi2/dof above
1e4, the data in other units than the model).

Notation
--------
==============  ==============================================================
``S``           node states, shape (n_nodes, n_states)
``hw``          half width of the local fits, s
``far``         RMS misfit of a simulated channel over the channel's range
==============  ==============================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .data import Channel, Measurements
from .errors import DataError
from .model import ModelSpec

__all__ = ["local_fit", "states_from_data", "initial_from_data", "apply_window", "window_guess", "parse_window", "StartPoint",
           "start_states", "start_checks", "result_checks", "units_check", "FAR"]

#: A simulation at the guess is "far from the data" when some measured state's RMS misfit exceeds this
#: fraction of the channel's range (max - min of the measured values).
FAR = 0.25

#: Unit mistakes the units check names: (what, factor by which the data are too small).
_LENGTH_UNITS = (("in km (multiply by 1000)", 1000.0), ("in feet (multiply by 0.3048)", 0.3048))
_SPEED_UNITS = (("in km/h (divide by 3.6)", 1 / 3.6), ("in km/s (multiply by 1000)", 1000.0),
                ("in ft/s (multiply by 0.3048)", 0.3048), ("in knots (multiply by 0.5144)", 0.5144))


def local_fit(times: np.ndarray, values: np.ndarray, at: np.ndarray, half_width: float,
              min_points: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Value and slope of a local quadratic least-squares fit at each time of ``at``.

    Parameters
    ----------
    times, values : ndarray, shape (n,)
        The samples (sorted times).
    at : ndarray, shape (m,)
    half_width : float
        Samples within ``half_width`` of a time are used; at least the ``min_points``
        nearest ones (across gaps and at the ends).

    Returns
    -------
    value, slope : ndarray, shape (m,)
    """
    t = np.asarray(times, float)
    y = np.asarray(values, float)
    at = np.asarray(at, float)
    val = np.empty(at.size)
    der = np.empty(at.size)
    k = min(max(min_points, 3), t.size)
    for i, a in enumerate(at):
        lo, hi = np.searchsorted(t, [a - half_width, a + half_width])
        if hi - lo < k:
            j = np.searchsorted(t, a)
            lo = max(0, min(j - k // 2, t.size - k))
            hi = lo + k
        dt = t[lo:hi] - a
        deg = 2 if hi - lo >= 3 and np.ptp(dt) > 0 else (1 if hi - lo >= 2 and np.ptp(dt) > 0 else 0)
        if deg == 0:
            val[i], der[i] = float(np.mean(y[lo:hi])), 0.0
            continue
        scale = max(float(np.max(np.abs(dt))), 1e-12)
        c = np.polynomial.polynomial.polyfit(dt / scale, y[lo:hi], deg)
        val[i] = c[0]
        der[i] = c[1] / scale
    return val, der


def _state_channels(spec: ModelSpec, data: Measurements) -> dict:
    """``{state symbol: channel}`` for the states an output measures directly."""
    out = {}
    for o in spec.outputs:
        if o.expr in spec.state_symbols and o.name in data.names:
            out[o.expr] = data[o.name]
    return out


def _half_width(ch: Channel, span: float) -> float:
    """Local-fit half width: about 1 % of the span, at least 2.5 sample spacings."""
    dt = float(np.median(np.diff(ch.times))) if ch.times.size > 1 else span
    return max(0.01 * span, 2.5 * dt)


def states_from_data(spec: ModelSpec, data: Measurements, times: np.ndarray,
                     fallback: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """States at ``times`` from the measured channels and kinematic relations.

    Parameters
    ----------
    spec : ModelSpec
    data : Measurements
    times : ndarray, shape (m,)
    fallback : ndarray, shape (m, n_states), optional
        Values for the states the data do not give (a simulation at the guess); where it is
        missing or not finite, the state's initial value.

    Returns
    -------
    S : ndarray, shape (m, n_states)
    source : dict
        ``{state name: "measured" | "kinematics" | "simulation" | "initial value"}``.
    """
    times = np.asarray(times, float)
    syms = spec.state_symbols
    span = spec.tf - spec.t0
    S = np.full((times.size, len(syms)), np.nan)
    slope = {}
    source = {}
    for sym, ch in _state_channels(spec, data).items():
        j = syms.index(sym)
        v, d = local_fit(ch.times, ch.values, times, _half_width(ch, span))
        S[:, j] = v
        slope[sym] = d
        source[str(sym)] = "measured"
    x, h, v, th = (spec.role(r) for r in ("downrange", "altitude", "speed", "flight_path_angle"))
    if th in syms and str(th) not in source and h in slope:
        jt = syms.index(th)
        if x in slope:
            S[:, jt] = np.arctan2(slope[h], slope[x])
            source[str(th)] = "kinematics"
        elif v in syms and str(v) in source:
            speed = S[:, syms.index(v)]
            ok = speed > max(1.0, 0.02 * float(np.nanmax(np.abs(speed))))
            if ok.any():
                sin = np.clip(slope[h][ok] / speed[ok], -1.0, 1.0)
                S[:, jt] = np.interp(times, times[ok], np.arcsin(sin))   # held at the slow end
                if fallback is not None:
                    fb = fallback[:, jt]
                    use = ~ok & np.isfinite(fb)
                    S[use, jt] = fb[use]
                source[str(th)] = "kinematics"
    if x in syms and str(x) not in source and str(th) in source and v in syms and str(v) in source:
        jx = syms.index(x)
        rate = S[:, syms.index(v)] * np.cos(S[:, syms.index(th)])
        x0 = _initial_value(spec, x, fallback, 0)
        S[:, jx] = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(times))])
        source[str(x)] = "kinematics"
    for j, st in enumerate(spec.states):
        if str(st.symbol) in source:
            continue
        col = fallback[:, j] if fallback is not None else np.full(times.size, np.nan)
        good = np.isfinite(col)
        if good.all():
            S[:, j] = col
            source[str(st.symbol)] = "simulation"
        else:
            S[:, j] = np.where(good, col, st.initial)
            source[str(st.symbol)] = "initial value"
    return S, source


def _initial_value(spec: ModelSpec, sym, fallback, row: int) -> float:
    j = spec.state_symbols.index(sym)
    if fallback is not None and np.isfinite(fallback[row, j]):
        return float(fallback[row, j])
    return float(spec.states[j].initial)


def initial_from_data(spec: ModelSpec, data: Measurements, t: float,
                      fallback: np.ndarray | None = None) -> tuple[dict, dict]:
    """The states at time ``t`` from the data (:func:`states_from_data` at one time).

    Returns
    -------
    values : dict
        ``{state symbol: value}``.
    source : dict
        ``{state name: how it was found}``.
    """
    S, source = states_from_data(spec, data, np.array([float(t)]),
                                 None if fallback is None else np.asarray(fallback, float).reshape(1, -1))
    return dict(zip(spec.state_symbols, S[0])), source


def parse_window(text: str, option: str = "--window") -> tuple[float, float]:
    """``"T0:T1"`` (seconds) -> ``(T0, T1)``; either end may be left out (``"20:"``, ``":45"``)
    and is then the model's horizon's end (returned as NaN)."""
    a, sep, b = str(text).partition(":")
    try:
        if not sep:
            raise ValueError
        lo = float(a) if a.strip() else math.nan
        hi = float(b) if b.strip() else math.nan
    except ValueError:
        raise DataError(f"{option} must be T0:T1 in seconds (for example 20:66, or 20: to the end), got {text!r}") from None
    if (math.isinf(lo) or math.isinf(hi)) or (not math.isnan(lo) and not math.isnan(hi) and not hi > lo):
        raise DataError(f"{option} {text}: the end must be after the start (seconds, finite)")
    return lo, hi


def apply_window(spec: ModelSpec, data: Measurements, window: Sequence[float], p: np.ndarray | None = None
                 ) -> tuple[ModelSpec, Measurements, list[str]]:
    """Cut the model and the data to a flight window ``(T0, T1)``.

    The data keep their samples in ``[T0, T1]``. When the window starts after the model's
    ``t0`` (in flight), the states that the data determine (measured ones, and the flight-path
    angle and downrange through the kinematic relations) get free initial values at ``T0``,
    guessed from the data; the other states start from the simulation at the guess ``p`` at
    ``T0`` (held, with a note). A NaN end is the horizon's.

    Returns
    -------
    spec, data, notes
    """
    from .simulate import simulate

    try:
        t0, t1 = (float(w) for w in window)
    except (TypeError, ValueError):
        raise DataError(f"window must be a pair (T0, T1) of times in seconds, got {window!r}") from None
    t0 = spec.t0 if math.isnan(t0) else t0
    t1 = spec.tf if math.isnan(t1) else t1
    if not (t1 > t0):
        raise DataError(f"window ({t0:g}, {t1:g}): the end must be after the start")
    if t0 < spec.t0 - 1e-9 or t1 > spec.tf + 1e-9:
        raise DataError(f"window ({t0:g}, {t1:g}) is not inside model {spec.name!r}'s horizon "
                        f"[{spec.t0:g}, {spec.tf:g}]; choose a window inside it")
    notes = []
    kept = []
    for c in data.channels:
        keep = (c.times >= t0) & (c.times <= t1)
        if keep.any():
            kept.append(c.select(keep))
    if not any(c.name in spec.output_names for c in kept):
        raise DataError(f"the data have no samples of {', '.join(spec.output_names)} in the window "
                        f"[{t0:g}, {t1:g}]")
    dropped = [c.name for c in data.channels if c.name not in {k.name for k in kept}]
    if dropped:
        notes.append(f"channel(s) {', '.join(dropped)} have no samples in the window [{t0:g}, {t1:g}]")
    data_w = Measurements(tuple(kept))
    if t0 <= spec.t0 + 1e-9:
        idle = [str(k) for k in spec.idle_knots(spec.t0, t1)]
        if idle:
            notes.append(f"{', '.join(idle)} {'acts' if len(idle) == 1 else 'act'} only after the window's end "
                         f"{t1:g} s: not estimated")
        return spec.windowed(spec.t0, t1), data_w, notes
    p = spec.guess if p is None else np.asarray(p, float)
    traj = simulate(spec, p, np.array([spec.t0, t0]), rtol=1e-8, atol=1e-8)
    fallback = traj.states[-1] if traj.success and np.all(np.isfinite(traj.states[-1])) else None
    values, source = initial_from_data(spec, data_w, t0, fallback)
    free = [s for s in spec.state_symbols if source.get(str(s)) in ("measured", "kinematics")]
    if not free:
        raise DataError(f"the window starts at t = {t0:g} s, in flight, but the data determine none of the states "
                        f"{', '.join(map(str, spec.state_symbols))} there (no output measures a state)")
    fixed = [str(s) for s in spec.state_symbols if s not in free]
    if fixed:
        how = ("the simulation at the guess" if fallback is not None else "their declared initial values (the "
               "simulation at the guess failed)")
        notes.append(f"window from t = {t0:g} s: the initial values of {', '.join(fixed)} are not determined by the "
                     f"data and start from {how}")
    spec_w = spec.windowed(t0, t1, initial=values, free=free)
    idle = [str(k) for k in spec.idle_knots(t0, t1)]
    if idle:
        notes.append(f"{', '.join(idle)} {'acts' if len(idle) == 1 else 'act'} only outside the window [{t0:g}, "
                     f"{t1:g}]: not estimated (the knot takes its active neighbour's value, which changes nothing "
                     "inside the window)")
    notes.append(f"window [{t0:g}, {t1:g}] s: initial values of {', '.join(map(str, free))} estimated (guesses from "
                 "the data)")
    return spec_w, data_w, notes


def window_guess(spec: ModelSpec, spec_w: ModelSpec, p: Sequence[float]) -> np.ndarray:
    """The windowed model's guess: ``p``'s values of the parameters it keeps, then the
    guesses of its initial states (from the data)."""
    p = np.asarray(p, float)
    old = dict(zip(spec.parameter_names, p))
    return np.array([old.get(n, g) for n, g in zip(spec_w.parameter_names, spec_w.guess)])


# ---------------------------------------------------------------------------
# Start trajectories and sanity checks
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StartPoint:
    """Node states to start IPOPT from.

    Attributes
    ----------
    states : ndarray, shape (n_nodes, n_states)
    source : str
        ``"simulation"`` or ``"data"``.
    notes : tuple of str
        What was wrong with the simulation at the guess, if anything.
    """

    states: np.ndarray
    source: str
    notes: tuple = ()


def _misfit(spec: ModelSpec, data: Measurements, times: np.ndarray, S: np.ndarray) -> dict[str, float]:
    """RMS misfit of each directly measured state over the channel's range."""
    out = {}
    for sym, ch in _state_channels(spec, data).items():
        j = spec.state_symbols.index(sym)
        good = np.isfinite(S[:, j])
        if not good.any():
            out[ch.name] = math.inf
            continue
        sim = np.interp(ch.times, times[good], S[good, j])
        rng = max(float(np.ptp(ch.values)), 1e-12)
        out[ch.name] = float(np.sqrt(np.mean((sim - ch.values) ** 2))) / rng
    return out


def start_checks(spec: ModelSpec, data: Measurements, times: np.ndarray, S: np.ndarray) -> list[str]:
    """What is implausible in a start (or fitted) trajectory ``S`` at ``times``, in the user's terms.

    Checks: the vehicle descends where the data climb (altitude), the flight path turns
    through more than 90 degrees, the trajectory leaves the ground.
    """
    notes = []
    h, th = spec.role("altitude"), spec.role("flight_path_angle")
    chans = _state_channels(spec, data)
    if h in spec.state_symbols:
        jh = spec.state_symbols.index(h)
        hs = S[:, jh]
        ch = chans.get(h)
        if ch is not None and ch.values.size > 2 and np.all(np.isfinite(hs)):
            climb = ch.values[-1] - ch.values[0]
            sim_at = np.interp(ch.times, times, hs)
            fall = sim_at[-1] - sim_at[0]
            if climb > 0 and fall < -0.1 * climb:
                i = int(np.argmax(hs))
                notes.append(f"the trajectory descends where the data climb (altitude {hs[0]:.4g} -> {hs[-1]:.4g} "
                             f"against measured {ch.values[0]:.4g} -> {ch.values[-1]:.4g}; it turns down near t = "
                             f"{times[i]:.3g} s)")
        if np.all(np.isfinite(hs)):
            low = min(0.0, float(hs[0]))
            if ch is not None:  # below the lowest measured altitude by more than 1 % of the measured range
                low = min(low, float(np.min(ch.values))) - max(1.0, 0.01 * float(np.ptp(ch.values)))
            else:
                low -= 1.0
            if np.any(hs < low):
                i = int(np.argmax(hs < low))
                notes.append(f"the trajectory flies into the ground at t = {times[i]:.3g} s")
    if th in spec.state_symbols:
        tt = S[:, spec.state_symbols.index(th)]
        good = np.isfinite(tt)
        if good.any():
            turn = np.abs(tt[good] - tt[good][0])
            if np.max(turn) > math.pi / 2:
                i = int(np.argmax(turn > math.pi / 2))
                notes.append(f"the flight path turns through {math.degrees(float(np.max(turn))):.0f} degrees (more than "
                             f"90 by t = {times[good][i]:.3g} s)")
    return notes


#: Below this unit factor (either way) a downrange channel's mismatch is reported, not refused: the
#: downrange of a steep flight follows the wind and the launch angle, and a 4 m/s surface wind made a
#: hybrid sounding rocket's GPS downrange 2.6 times the model's at its guess (Wren-H), which read as feet.
DOWNRANGE_FIRM_FACTOR = 10.0


def units_check(spec: ModelSpec, data: Measurements, times: np.ndarray, S: np.ndarray, *,
                firm: bool = True) -> list[str]:
    """Likely unit mistakes: a measured altitude, downrange or speed whose size differs from the
    model's (the simulation at the guess ``S``) by a unit factor (km, feet, km/h, knots).

    Parameters
    ----------
    firm : bool
        True: the mismatches that refuse the data -- every one in altitude and speed, and in
        downrange those by a factor of :data:`DOWNRANGE_FIRM_FACTOR` or more (km). False: the
        others (a downrange channel that looks in feet), which are only reported: physics moves a
        steep flight's downrange by a few times as well.

    Returns
    -------
    list of str
        One message per channel, naming the likely unit and the fix.
    """
    return [text for text, strong in _unit_mismatches(spec, data, times, S) if strong == firm]


def _unit_mismatches(spec: ModelSpec, data: Measurements, times: np.ndarray, S: np.ndarray) -> list[tuple]:
    """``(message, firm)`` of each channel that looks in another unit (:func:`units_check`)."""
    out = []
    for sym, ch in _state_channels(spec, data).items():
        role = next((r for r in ("altitude", "downrange", "speed") if spec.role(r) == sym), None)
        if role is None:
            continue
        j = spec.state_symbols.index(sym)
        good = np.isfinite(S[:, j])
        if not good.any():
            continue
        sim = np.interp(ch.times, times[good], S[good, j])
        a, b = float(np.max(np.abs(sim))), float(np.max(np.abs(ch.values)))
        if not (a > 0 and b > 0):
            continue
        ratio = a / b        # the factor the data would need
        for what, factor in (_SPEED_UNITS if role == "speed" else _LENGTH_UNITS):
            if abs(math.log(ratio / factor)) < math.log(1.6) and abs(math.log(ratio)) > math.log(2.5):
                strong = role != "downrange" or abs(math.log(factor)) >= math.log(DOWNRANGE_FIRM_FACTOR)
                text = (f"channel {ch.name!r} ({role}) looks {what}: its largest value is {b:.4g} but the model "
                        f"at the guess reaches {a:.4g}, {ratio:.3g} times more; convert the column (or, if the "
                        "values are right, check the model's guess)")
                if not strong:
                    text += (" -- not refused: a steep flight's downrange also moves by a few times with the wind "
                             "and the launch angle")
                out.append((text, strong))
                break
    return out


def _scale_gap(spec: ModelSpec, data: Measurements, times: np.ndarray, S: np.ndarray) -> list[str]:
    """Channels whose values are over a million times larger than the model's at the guess."""
    out = []
    for sym, ch in _state_channels(spec, data).items():
        j = spec.state_symbols.index(sym)
        a, b = float(np.max(np.abs(S[:, j]))), float(np.max(np.abs(ch.values)))
        if a > 0 and b > 1e6 * a:
            out.append(f"channel {ch.name!r} reaches {b:.3g}, {b / a:.1g} times the model's {a:.3g} at the guess: "
                       "check the data's units and scale")
    return out


def start_states(spec: ModelSpec, data: Measurements, times: np.ndarray, p: np.ndarray) -> StartPoint:
    """The node states to start from: the simulation at ``p`` when it runs and stays near the
    data, else the data (:func:`states_from_data`), with notes that say why.

    Raises
    ------
    DataError
        The data look like they are in other units than the model (:func:`units_check`).
    """
    from .simulate import simulate

    traj = simulate(spec, p, times, rtol=1e-8, atol=1e-8)
    S = np.array(traj.states, float)
    finite = np.all(np.isfinite(S), axis=1)
    problems, doubts = [], []
    if not traj.success or not finite.all():
        problems.append(f"the simulation at the guess failed ({traj.message or 'non-finite states'})")
    if finite.any():
        units = _unit_mismatches(spec, data, times[finite], S[finite])
        if any(strong for _, strong in units):
            raise DataError("; ".join(text for text, strong in units if strong))
        doubts = [text for text, strong in units if not strong]                  # reported, not refused
        scale = _scale_gap(spec, data, times[finite], S[finite])
        if scale:
            # data orders of magnitude off the model: starting from them would hide the mistake
            return StartPoint(_held(S, spec, p), "simulation", tuple(problems + scale + doubts))
    if not problems:
        problems += start_checks(spec, data, times, S)
        far = {k: v for k, v in _misfit(spec, data, times, S).items() if v > FAR}
        if far:
            problems.append("the simulation at the guess is far from the data (RMS misfit " + ", ".join(
                f"{k} {100 * v:.0f} %" for k, v in far.items()) + " of the measured range)")
    if not problems:
        return StartPoint(S, "simulation", tuple(doubts))
    Sd, source = states_from_data(spec, data, times, fallback=np.where(np.isfinite(S), S, np.nan))
    how = ", ".join(f"{k} {v}" for k, v in source.items())
    if all(v in ("simulation", "initial value") for v in source.values()):
        held = _held(S, spec, p)
        return StartPoint(held, "simulation", tuple(
            doubts + problems + ["no state is measured directly, so the start cannot follow the data; states held "
                                 "at the simulation's last value"]))
    return StartPoint(Sd, "data", tuple(doubts + problems
                                        + [f"the collocation states start from the data ({how}) instead"]))


def _held(S: np.ndarray, spec: ModelSpec, p) -> np.ndarray:
    good = np.all(np.isfinite(S), axis=1)
    out = S.copy()
    last = S[good][-1] if good.any() else spec.initial_state(p)
    out[~good] = last
    return out


def result_checks(fit) -> list[str]:
    """What makes a converged fit not credible, with what to check.

    ``fit`` is an :class:`~rocketid.solve.EstimationResult`. Checks: every parameter at a
    bound, chi2/dof above 1e4, the fitted trajectory descends where the data climb or turns
    the flight path through more than 90 degrees.
    """
    notes = []
    n_p = len(fit.spec.parameters)
    at = fit.active_bounds()
    if n_p and len(at) == n_p:
        notes.append("every parameter is at a bound: this is not an estimate. Check the units of the data, the "
                     "model's initial state and horizon, and the start trajectory (notes above)")
    if fit.chi2_per_dof > 1e4:
        notes.append(f"chi2/dof = {fit.chi2_per_dof:.3g}: the model is nowhere near the data. Check the units of the "
                     "data (altitude in m, speed in m/s), the sigmas, the time origin and the model's initial state")
    try:
        traj_notes = start_checks(fit.spec, fit.prepared.measurements, fit.node_times, fit.state_trajectories)
    except (ValueError, IndexError):  # pragma: no cover - defensive: a check must not break a result
        traj_notes = []
    notes += [f"the fitted {n[4:]}" if n.startswith("the trajectory") else f"in the fit, {n}" for n in traj_notes]
    return notes
