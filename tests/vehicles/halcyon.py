"""Halcyon-8: an 8 t liquid-propellant first stage, declared as a user would.

Written from the user documentation only (docs/own-vehicle.md, docs/cli.md "Model files",
``rocketid.physics.ascent``), for the blind study (``tests/blind_study``):

==============  ===============================================================
mass            m(t) = 8 000 - 55 t kg (80 s burn, 3 600 kg at burn-out)
thrust          150 kN, the sea-level thrust of a static firing, constant
reference area  pi * 0.6^2 m^2 (1.2 m diameter)
drag            CD(M) piecewise linear in Mach on knots 0, 0.8, 1.05, 1.25, 1.6,
                2.5, 3.5, 4.5
lift            CL = CL_alpha * alpha (CL_alpha a constant parameter, /rad)
attitude        a sampled pitch-attitude program phi(t) (every 0.5 s): held at
                the rail's 87 deg for 3 s, a 4 deg pitch-over to 11 s, then a
                pitch-down at 0.55 deg/s, with a +-1.2 deg excitation of period
                17 s; the attack angle alpha = phi - theta is a definition
start           rail exit: x = 0, h = 5 m, v = 20 m/s, theta = 87 deg
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    x, h, v at 10 Hz, sigma 3 m, 3 m, 0.3 m/s
==============  ===============================================================
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

M0 = 8_000.0
MDOT = 55.0
THRUST_SL = 150_000.0
DIAMETER = 1.2
AREA = math.pi * (DIAMETER / 2) ** 2
TF = 80.0
START = (0.0, 5.0, 20.0, math.radians(87.0))
MACH_KNOTS = (0.0, 0.8, 1.05, 1.25, 1.6, 2.5, 3.5, 4.5)
CD_TRUTH = (0.30, 0.32, 0.55, 0.53, 0.44, 0.35, 0.30, 0.27)
CL_ALPHA_TRUTH = 3.0
PROGRAM_STEP = 0.5
SIGMA = {"x": 3.0, "h": 3.0, "v": 0.3}


def pitch_program(t) -> np.ndarray:
    """Pitch attitude phi (rad) at ``t`` (s)."""
    t = np.asarray(t, float)
    deg = (87.0 - 4.0 * np.clip((t - 3.0) / 8.0, 0.0, 1.0) - 0.55 * np.clip(t - 11.0, 0.0, None)
           + 1.2 * np.sin(2 * math.pi * (t - 11.0) / 17.0) * (t >= 11.0))
    return np.radians(deg)


def program_table() -> tuple[np.ndarray, np.ndarray]:
    """The sampled attitude program (times, phi) every PROGRAM_STEP s."""
    tt = np.arange(0.0, TF + 1e-9, PROGRAM_STEP)
    return tt, pitch_program(tt)


def build_model():
    """Halcyon-8: CD(Mach) table and CL_alpha to estimate."""
    m = Model("Halcyon-8", 0.0, TF, description="8 t liquid stage, 150 kN sea-level thrust, CD(Mach), pitch program")
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    tt, phi_values = program_table()
    phi = m.input("phi", times=tt, values=phi_values)
    alpha = m.define("alpha", phi - st.theta)
    cd = m.table("CD", fc.mach, MACH_KNOTS, 0.35, bounds=(0.01, 2.0), nominal=0.35)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=3.0)
    ascent_dynamics(m, st, fc, thrust=m.constant("P_sl", THRUST_SL), mass=M0 - MDOT * m.t,
                    area=m.constant("S_ref", AREA), cd=cd, cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    values = {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}
    values["CL_alpha"] = CL_ALPHA_TRUTH
    return values


def sample_times():
    """10 Hz over the burn: t = 0.1 k s, k = 1..800."""
    return 0.1 * np.arange(1, 801)
