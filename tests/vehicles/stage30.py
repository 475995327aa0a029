"""Stage-30: a 30 t first stage declared the way a user declares a vehicle.

This file is a user's model file (``rocketid diagnose --model tests/vehicles/stage30.py``):
it builds the model from rocketid's public building blocks only. It is the third vehicle of
the hidden-effect study (``tests/study``), chosen unlike RA-66 in every number:

==============  ===============================================================
mass            m(t) = 30 000 - 240 t kg (66 s burn)
thrust          610 kN, the sea-level thrust of a static firing (constant in this
                model: the nozzle's altitude gain is what the study hides)
reference area  pi * 0.7^2 m^2 (1.4 m diameter)
drag            CD(M) piecewise linear in Mach on knots 0, 0.8, 1.15, 1.6, 2.3,
                3.0, 3.8 (truth 0.24, 0.26, 0.50, 0.46, 0.37, 0.31, 0.27)
lift            CL = CL_alpha * alpha (truth 2.5 /rad)
attitude        a sampled program (every 0.5 s, linearly interpolated): vertical
                for 3 s, a -2 deg pitch kick 3-11 s, then a +-1.5 deg attack-angle
                excitation of period 23 s (so that CL_alpha is identifiable)
start           x = h = 0, v = 5 m/s (released at speed), theta = 89.8 deg
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    x, h, v at 100 Hz, sigma 1 m, 1 m, 1 m/s
==============  ===============================================================
"""

from __future__ import annotations

import math

import numpy as np

from rocketid.model import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

M0 = 30_000.0
MDOT = 240.0
THRUST_SL = 610_000.0
AREA = math.pi * 0.7 ** 2
MACH_KNOTS = (0.0, 0.8, 1.15, 1.6, 2.3, 3.0, 3.8)
CD_TRUTH = (0.24, 0.26, 0.50, 0.46, 0.37, 0.31, 0.27)
CL_ALPHA_TRUTH = 2.5
V0 = 5.0
THETA0_DEG = 89.8
TF = 66.0
PROGRAM_STEP = 0.5


def attitude_program(times: np.ndarray) -> np.ndarray:
    """The attack-angle program, rad, at ``times`` (s): what a user's table would hold."""
    t = np.asarray(times, dtype=float)
    kick = np.where((t >= 3.0) & (t <= 11.0), -math.radians(2.0) * np.sin(math.pi * (t - 3.0) / 8.0) ** 2, 0.0)
    exc = np.where(t > 11.0, math.radians(1.5) * np.sin(2 * math.pi * (t - 11.0) / 23.0), 0.0)
    return kick + exc


def program_table() -> tuple[np.ndarray, np.ndarray]:
    """The sampled attitude program (times, alpha) every :data:`PROGRAM_STEP` s."""
    t = np.arange(0.0, TF + 1e-9, PROGRAM_STEP)
    return t, attitude_program(t)


def build_model() -> Model:
    """The Stage-30 model: CD(Mach) table and CL_alpha to estimate."""
    m = Model("Stage-30", 0.0, TF, description="30 t stage, sea-level thrust 610 kN, CD(Mach), sampled attitude")
    st = ascent_states(m, initial=(0.0, 0.0, V0, math.radians(THETA0_DEG)))
    fc = flight_conditions(m, st, atmosphere="us76")
    tt, aa = program_table()
    alpha = m.input("alpha", times=tt, values=aa)
    cd = m.table("CD", fc.mach, MACH_KNOTS, 0.35, bounds=(0.01, 2.0), nominal=0.35)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
    ascent_dynamics(m, st, fc, thrust=m.constant("P_sl", THRUST_SL), mass=M0 - MDOT * m.t,
                    area=m.constant("S_ref", AREA), cd=cd, cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=1.0)
    return m


def truth(spec) -> np.ndarray:
    """The true parameter vector (CD table, CL_alpha)."""
    values = {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}
    values["CL_alpha"] = CL_ALPHA_TRUTH
    return spec.parameter_vector({k: v for k, v in values.items() if k in spec.parameter_names})


def sample_times() -> np.ndarray:
    """100 Hz samples over the burn."""
    return np.arange(1, int(round(TF * 100)) + 1) * 0.01
