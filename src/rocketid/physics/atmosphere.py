"""Standard-atmosphere density and speed of sound as differentiable SymPy expressions.

Two models of air density are offered, both as functions of the *geometric* altitude
``h`` (m) above sea level:

* ``"yang1983"`` -- the chapter's choice, "Yang's model": Yang Bingwei, "Formula
  representation of standard-atmosphere parameters", Journal of Astronautics (Yuhang
  Xuebao), 1983.  Closed-form layer fits to the US Standard Atmosphere 1976 up to
  47.3501 km geometric altitude (see :func:`yang1983_density`).
* ``"us76"`` -- the U.S. Standard Atmosphere, 1976 (NOAA/NASA/USAF, NOAA-S/T 76-1562,
  Washington D.C., 1976), its seven layers from 0 to 86 km geometric altitude,
  built here from the standard's defining constants and hydrostatic formulas.

Notation
--------
h
    Geometric altitude above sea level, m (the ``Z`` of the standard).  Every public
    function takes ``h``; it may be a number or any SymPy expression (a ``Symbol``, or a
    state of an ODE model), so the results can be differentiated with ``sympy.diff``.
H
    Geopotential altitude, m' (the standard's geopotential metre),
    ``H = r0 h / (r0 + h)`` with the standard's radius ``r0 = R0_US76 = 6 356 766 m``
    (not the Earth radius of the trajectory model: using ``Re`` instead changes the
    density by about 2e-5 relative at 20 km).
T
    Molecular-scale temperature ``T_M``, K.  It equals the kinetic temperature below
    80 km geometric; between 80 and 86 km the kinetic temperature is ``T_M M/M0`` with
    ``M/M0 >= 0.9996``.  Density and speed of sound in the standard are defined with
    ``T_M`` (rho = P M0 / (R* T_M), C_s = sqrt(gamma R* T_M / M0)), so both are exact.
P, rho, a
    Pressure (Pa), density (kg/m^3), speed of sound (m/s).

Layers are written as ``sympy.Piecewise`` expressions whose conditions are on the
geometric altitude ``h`` (``h < boundary``), ordered from the bottom, so that
``sympy.lambdify(..., "numpy")`` turns them into a ``numpy.select``.  ``numpy.select``
evaluates *every* branch at every point, so every branch is written to be finite and
warning-free for -1 km <= h <= 86 km: the only branch whose base quantity reaches zero
in that range is the lowest layer (``T = 288.15 K - 6.5 K/km * H`` and Yang's
``W = 1 - H/44.3308`` vanish at H = 44.33 km), and there the base is clamped from below
with ``sympy.Max`` at a value far under its smallest in-layer value (``W >= 0.75`` in the
layer, clamp at 0.1; ``T >= 216.65 K``, clamp at 1 K).  The clamp never binds inside the
layer, so values and derivatives there are the unclamped ones.  Below 0 m the lowest
layer is continued; above 86 km the top layer (71-84.852 km' geopotential) is continued
(the standard changes its formulation there).

Public copies of Yang's fits carry typos (1.5898 for 0.15898, -35.1829 for -35.1629);
the coefficients here are the ones that reproduce the 1976 tables, checked in
``tests/test_atmosphere.py``.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import sympy as sp

__all__ = [
    "R0_US76",
    "RHO_SL",
    "R_STAR",
    "M0",
    "G0",
    "GAMMA",
    "T0",
    "P0",
    "US76_LAYERS",
    "US76_BOUNDARIES",
    "YANG1983_BOUNDARIES",
    "MODELS",
    "geopotential_altitude",
    "geometric_altitude",
    "yang1983_density",
    "us76_temperature",
    "us76_pressure",
    "us76_density",
    "us76_speed_of_sound",
    "density",
    "speed_of_sound",
]

# --------------------------------------------------------------------------------------
# Constants of the U.S. Standard Atmosphere 1976 (its Table 2 / section 1.2).
# --------------------------------------------------------------------------------------
R0_US76 = 6356766.0
"""Earth radius used by the 1976 standard for the geopotential conversion, m."""
RHO_SL = 1.2250
"""Sea-level density, kg/m^3."""
R_STAR = 8.31432
"""Universal gas constant as the 1976 standard gives it, N m / (kmol K) * 1e-3 = J/(mol K)."""
M0 = 0.0289644
"""Sea-level mean molecular weight of air, kg/mol."""
G0 = 9.80665
"""Standard gravity, m/s^2 (m^2 / (s^2 m') in the geopotential formulas)."""
GAMMA = 1.4
"""Ratio of specific heats of air."""
T0 = 288.15
"""Sea-level temperature, K."""
P0 = 101325.0
"""Sea-level pressure, Pa."""

_HYDRO = G0 * M0 / R_STAR  # g0 M0 / R*, K/m' (34.1632 K/km')

# Geopotential base heights (m') and lapse rates (K/m') of the seven layers, 0-86 km.
_US76_HB = (0.0, 11000.0, 20000.0, 32000.0, 47000.0, 51000.0, 71000.0)
_US76_LB = (-6.5e-3, 0.0, 1.0e-3, 2.8e-3, 0.0, -2.8e-3, -2.0e-3)
_US76_H_TOP = 84852.0  # geopotential height of 86 km geometric, m'

# Clamps (see the module docstring): never active inside the layer that uses them.
_T_FLOOR = 1.0  # K
_W_FLOOR = 0.1  # Yang's W in the lowest layer is >= 0.7519 there


def _build_us76_layers() -> tuple[tuple[float, float, float, float], ...]:
    """Base geopotential height, lapse rate, base temperature and base pressure per layer.

    Base temperatures and pressures are propagated upward from (T0, P0) with the
    standard's formulas (its eqs. 23, 33a and 33b).
    """
    layers = []
    tb, pb = T0, P0
    for i, (hb, lb) in enumerate(zip(_US76_HB, _US76_LB)):
        layers.append((hb, lb, tb, pb))
        h_next = _US76_HB[i + 1] if i + 1 < len(_US76_HB) else _US76_H_TOP
        dh = h_next - hb
        t_next = tb + lb * dh
        if lb == 0.0:
            p_next = pb * math.exp(-_HYDRO * dh / tb)
        else:
            p_next = pb * (tb / t_next) ** (_HYDRO / lb)
        tb, pb = t_next, p_next
    return tuple(layers)


US76_LAYERS = _build_us76_layers()
"""Per layer ``(H_b [m'], L_b [K/m'], T_b [K], P_b [Pa])`` of the 1976 standard."""


def geometric_altitude(H, radius: float = R0_US76):
    """Geometric altitude from geopotential altitude.

    Parameters
    ----------
    H : float or sympy.Expr
        Geopotential altitude, m'.
    radius : float, optional
        Radius of the conversion, m (default: the 1976 standard's ``R0_US76``).

    Returns
    -------
    float or sympy.Expr
        ``h = r0 H / (r0 - H)``, m.
    """
    return radius * H / (radius - H)


US76_BOUNDARIES = tuple(geometric_altitude(hb) for hb in _US76_HB[1:])
"""Geometric altitudes (m) of the US76 layer boundaries (11, 20, 32, 47, 51, 71 km')."""

YANG1983_BOUNDARIES = (11019.1, 20063.1, 32161.9, 47350.1)
"""Geometric altitudes (m) of Yang's layer boundaries, as Yang gives them."""

MODELS = ("yang1983", "us76")
"""Valid density model names."""


def geopotential_altitude(h, radius: float = R0_US76):
    """Geopotential altitude from geometric altitude.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m.
    radius : float, optional
        Radius of the conversion, m (default: the 1976 standard's ``R0_US76``).

    Returns
    -------
    sympy.Expr
        ``H = r0 h / (r0 + h)``, m'.
    """
    h = sp.sympify(h)
    r0 = sp.Float(radius)
    return r0 * h / (r0 + h)


def _piecewise(h, exprs, boundaries) -> sp.Piecewise:
    """``Piecewise`` selecting ``exprs[i]`` for ``boundaries[i-1] <= h < boundaries[i]``."""
    if len(exprs) != len(boundaries) + 1:
        raise ValueError("need one more expression than boundaries")
    pieces = [(e, sp.StrictLessThan(h, sp.Float(b))) for e, b in zip(exprs, boundaries)]
    pieces.append((exprs[-1], True))
    return sp.Piecewise(*pieces)


def _us76_layer_state(h, i):
    """Temperature, clamped temperature and pressure expressions of US76 layer ``i``."""
    hb, lb, tb, pb = US76_LAYERS[i]
    H = geopotential_altitude(h)
    if lb == 0.0:
        t = sp.Float(tb)
        p = sp.Float(pb) * sp.exp(sp.Float(-_HYDRO / tb) * (H - sp.Float(hb)))
        return t, t, p
    t = sp.Float(tb) + sp.Float(lb) * (H - sp.Float(hb))
    t_safe = sp.Max(t, sp.Float(_T_FLOOR)) if lb < 0.0 else t
    p = sp.Float(pb) * (sp.Float(tb) / t_safe) ** sp.Float(_HYDRO / lb)
    return t, t_safe, p


def _us76_layer_density(h, i):
    _, t_safe, p = _us76_layer_state(h, i)
    return p * sp.Float(M0 / R_STAR) / t_safe


def us76_temperature(h) -> sp.Piecewise:
    """US Standard Atmosphere 1976 (molecular-scale) temperature.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m; the layers cover 0-86 km (the lowest layer is continued
        below 0, the top one above 86 km).

    Returns
    -------
    sympy.Piecewise
        ``T_b + L_b (H - H_b)`` per layer, K, with ``H`` the geopotential altitude.
        Not clamped: it becomes negative in the lowest layer's expression above 44 km,
        which is harmless as the layer is only selected below 11.019 km.
    """
    h = sp.sympify(h)
    exprs = [_us76_layer_state(h, i)[0] for i in range(len(US76_LAYERS))]
    return _piecewise(h, exprs, US76_BOUNDARIES)


def us76_pressure(h) -> sp.Piecewise:
    """US Standard Atmosphere 1976 pressure.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m (0-86 km; continued below and above).

    Returns
    -------
    sympy.Piecewise
        Pressure, Pa: ``P_b (T_b / T)^(g0 M0 / (R* L_b))`` in gradient layers,
        ``P_b exp(-g0 M0 (H - H_b) / (R* T_b))`` in isothermal ones, with the base
        pressures ``P_b`` propagated from 101325 Pa (see ``US76_LAYERS``).
    """
    h = sp.sympify(h)
    exprs = [_us76_layer_state(h, i)[2] for i in range(len(US76_LAYERS))]
    return _piecewise(h, exprs, US76_BOUNDARIES)


def us76_density(h) -> sp.Piecewise:
    """US Standard Atmosphere 1976 density.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m (0-86 km; continued below and above).

    Returns
    -------
    sympy.Piecewise
        ``rho = P M0 / (R* T)``, kg/m^3.
    """
    h = sp.sympify(h)
    exprs = [_us76_layer_density(h, i) for i in range(len(US76_LAYERS))]
    return _piecewise(h, exprs, US76_BOUNDARIES)


def us76_speed_of_sound(h) -> sp.Piecewise:
    """US Standard Atmosphere 1976 speed of sound.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m (0-86 km; continued below and above).

    Returns
    -------
    sympy.Piecewise
        ``a = sqrt(gamma R* T / M0)``, m/s (340.294 m/s at sea level).
    """
    h = sp.sympify(h)
    c = sp.Float(GAMMA * R_STAR / M0)
    exprs = [sp.sqrt(c * _us76_layer_state(h, i)[1]) for i in range(len(US76_LAYERS))]
    return _piecewise(h, exprs, US76_BOUNDARIES)


def us76_offset_log_pressure_ratio(h, dT) -> sp.Piecewise:
    """``ln(p / p_std)`` of an atmosphere ``dT`` kelvin warmer than the 1976 standard at every altitude, at the
    standard's sea-level pressure (a hot or a cold day).

    The hydrostatic equation ``d ln p / dH = -g0 M0 / (R* T)`` with ``T = T_std + dT`` gives
    ``ln(p / p_std) = (g0 M0 / R*) int_0^H (1/T_std - 1/(T_std + dT)) dH'``, in closed form per layer:
    ``(1/L_b) ln(T (T_b + dT) / ((T + dT) T_b))`` in a gradient layer, ``(H - H_b)(1/T_b - 1/(T_b + dT))``
    in an isothermal one, each layer's base value carried up from the layers below (exact, no expansion in
    ``dT``).

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m (0-86 km; the lowest layer is continued below 0, the top one above).
    dT : float or sympy.Expr
        The temperature offset, K.

    Returns
    -------
    sympy.Piecewise
    """
    h, dT = sp.sympify(h), sp.sympify(dT)
    H = geopotential_altitude(h)
    tops = _US76_HB[1:] + (_US76_H_TOP,)
    c = sp.Float(_HYDRO)
    base = sp.S.Zero
    exprs = []
    for (hb, lb, tb, _), top in zip(US76_LAYERS, tops):
        Tb = sp.Float(tb)
        if lb == 0.0:
            exprs.append(base + c * (H - sp.Float(hb)) * (1 / Tb - 1 / (Tb + dT)))
            base = base + c * sp.Float(top - hb) * (1 / Tb - 1 / (Tb + dT))
        else:
            t = Tb + sp.Float(lb) * (H - sp.Float(hb))
            exprs.append(base + c / sp.Float(lb) * sp.log(t * (Tb + dT) / ((t + dT) * Tb)))
            t_top = sp.Float(tb + lb * (top - hb))
            base = base + c / sp.Float(lb) * sp.log(t_top * (Tb + dT) / ((t_top + dT) * Tb))
    return _piecewise(h, exprs, US76_BOUNDARIES)


# Yang (1983): rho / rho_SL = c * W^a per layer, W a function of H in km.
_YANG_LAYERS = (
    # (c, a, W(Hkm)) -- coefficients of Yang 1983 without the typos of public copies
    (1.0, 4.2559, lambda Hk: sp.Max(1 - Hk / sp.Float(44.3308), sp.Float(_W_FLOOR))),
    (0.15898, 1.0, lambda Hk: sp.exp((sp.Float(14.9647) - Hk) / sp.Float(6.3416))),
    (0.032722, -35.1629, lambda Hk: 1 + (Hk - sp.Float(24.9021)) / sp.Float(221.552)),
    (3.2617e-3, -13.2011, lambda Hk: 1 + (Hk - sp.Float(39.7500)) / sp.Float(89.4107)),
)


def yang1983_density(h) -> sp.Piecewise:
    """Air density from Yang Bingwei's (1983) closed-form fits to the 1976 standard.

    With the geopotential altitude ``H`` in km (``R0_US76`` conversion),
    ``rho = 1.2250 kg/m^3 * c * W^a`` with, per geometric-altitude layer:

    ===================  ==================================  ==========  =========
    h range, km          W                                   c           a
    ===================  ==================================  ==========  =========
    below 11.0191        1 - H/44.3308                       1           4.2559
    11.0191 - 20.0631    exp((14.9647 - H)/6.3416)           0.15898     1
    20.0631 - 32.1619    1 + (H - 24.9021)/221.552           0.032722    -35.1629
    32.1619 - 47.3501    1 + (H - 39.7500)/89.4107           3.2617e-3   -13.2011
    ===================  ==================================  ==========  =========

    Above 47.3501 km (Yang's fits stop there) the US76 density of the layers with
    geopotential bases 47, 51 and 71 km is used (see :func:`us76_density`); that
    extension is this package's choice, not Yang's.  The fits agree with the 1976
    standard to about 3e-5 relative, so the density jumps by up to about 4e-5
    relative at Yang's internal boundaries (1.5e-5 at 11.0191 km, 3.7e-5 at 20.0631
    and 32.1619 km) and by 2.3e-6 where the US76 layers take over.

    Parameters
    ----------
    h : float or sympy.Expr
        Geometric altitude, m (-1 km to 86 km is the checked range).

    Returns
    -------
    sympy.Piecewise
        Density, kg/m^3, with conditions on ``h``.

    Notes
    -----
    In the lowest layer ``W`` is clamped from below at 0.1 (``sympy.Max``) so that
    the branch stays finite where ``numpy.select`` evaluates it outside its layer
    (``W`` reaches 0 at H = 44.33 km); inside the layer ``W >= 0.75``, so the clamp
    never binds.  The other ``W`` stay positive for all h above -49 km.
    """
    h = sp.sympify(h)
    Hk = geopotential_altitude(h) / 1000
    exprs = [
        sp.Float(RHO_SL * c) * (w(Hk) if a == 1.0 else w(Hk) ** sp.Float(a))
        for c, a, w in _YANG_LAYERS
    ]
    # Continue with the US76 layers above Yang's top (47 km' = 47.3501 km geometric).
    n_top = _US76_HB.index(47000.0)
    exprs += [_us76_layer_density(h, i) for i in range(n_top, len(US76_LAYERS))]
    boundaries = list(YANG1983_BOUNDARIES) + list(US76_BOUNDARIES[n_top:])
    return _piecewise(h, exprs, boundaries)


# --------------------------------------------------------------------------------------
# NumPy evaluators
# --------------------------------------------------------------------------------------
_H = sp.Symbol("h", real=True)
_BUILDERS = {
    ("density", "yang1983"): yang1983_density,
    ("density", "us76"): us76_density,
    ("speed_of_sound", "us76"): us76_speed_of_sound,
}
_CACHE: dict[tuple[str, str], Callable[[np.ndarray], np.ndarray]] = {}


def _evaluator(quantity: str, model: str) -> Callable[[np.ndarray], np.ndarray]:
    key = (quantity, model)
    fn = _CACHE.get(key)
    if fn is None:
        fn = sp.lambdify(_H, _BUILDERS[key](_H), modules="numpy")
        _CACHE[key] = fn
    return fn


def _evaluate(quantity: str, model: str, h):
    h_arr = np.asarray(h, dtype=float)
    out = np.asarray(_evaluator(quantity, model)(h_arr), dtype=float)
    out = np.broadcast_to(out, h_arr.shape)
    if out.ndim == 0:
        return float(out)
    return np.array(out)


def density(h, model: str = "yang1983"):
    """Air density, evaluated numerically (vectorized).

    Parameters
    ----------
    h : float or array_like
        Geometric altitude, m.
    model : {"yang1983", "us76"}, optional
        ``"yang1983"`` (default, the chapter's model, see :func:`yang1983_density`) or
        ``"us76"`` (:func:`us76_density`).

    Returns
    -------
    float or numpy.ndarray
        Density, kg/m^3, a float for scalar ``h``, else an array of ``h``'s shape.

    Raises
    ------
    ValueError
        If ``model`` is not one of ``MODELS``.
    """
    if model not in MODELS:
        raise ValueError(
            f"unknown atmosphere model {model!r}; valid choices: "
            + ", ".join(repr(m) for m in MODELS)
        )
    return _evaluate("density", model, h)


def speed_of_sound(h):
    """Speed of sound of the 1976 standard, evaluated numerically (vectorized).

    Parameters
    ----------
    h : float or array_like
        Geometric altitude, m.

    Returns
    -------
    float or numpy.ndarray
        Speed of sound, m/s (see :func:`us76_speed_of_sound`).
    """
    return _evaluate("speed_of_sound", "us76", h)
