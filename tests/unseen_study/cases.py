"""The cases of the unseen-vehicle evaluation: Kestrel-S with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed, and which catalogue
families count as the right answer (``right``: every family in the final model must be one of
these, and each of ``needed`` must be there). Sizes, relative to Kestrel-S (thrust 55 -> 29 kN,
1.5 t, 0.5 m diameter, Mach 0.1 -> 3.2, 12 m -> 18.6 km):

- warm motor: thrust curve 3 % faster and higher (a grain about 15-20 K warm);
- back-pressure: a 0.25 m exit diameter (A_e 0.05 m^2: 5 kN in vacuum, 4 kN = 13 % of the
  thrust at burn-out altitude), thrust stated at sea level;
- headwind: 5 m/s at the rail, 23 m/s at 10 km (shear from a surface value, monotone aloft);
- warm day: +8 K over the whole column (density -2.7 % at the ground, +0.6 % at 10 km, +3.3 % at 15 km);
- misalignment 0.3 deg from t = 0;
- Earth rotation at Andoya (69.3 N), launched north-east (azimuth 45 deg);
- altitude sensor bias drifting from 3 m to 9 m over the 40 s (0.15 m/s);
- time-tag offset 20 ms (half a sample at 25 Hz);
- a start mass 25 kg above the declared 1500 kg (1.7 %): when this case was written no catalogue
  effect had this shape (the diagnosis called a thrust profile explained); the catalogue's
  ``start_mass`` was added after that failure was measured, so this case is no longer evidence on
  unseen physics -- it checks that the effect, once in the catalogue, wins against the thrust
  profile that mimics it;
- two pairs; eight clean seeds;
- ``SEALED``: three cases kept from the team until a re-run; ``FRESH``: eight more pairs made on 2026-11-28 as a
  probe of combinations the diagnosis had not met.
"""

from __future__ import annotations

import math

from study_harness import Case

from .truth import Hidden

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow"})
# burn_rate (thrust and mass flow together on a faster motor clock, the hot motor's own physics) was added to the
# catalogue after the study was written (2026-11-26): right for the hot motor, whose truth is that change
HOT = THRUST | {"burn_rate"}


MIS = math.radians(0.3)

CASES = (
    Case("hot-motor", Hidden(hot_motor=1.03), 301,
         "thrust curve 3 % faster and higher, P(t) = 1.03 P_tab(1.03 t), mass flow with it",
         right=HOT, needed=frozenset({"thrust_level", "thrust_profile", "burn_rate"}), sizes=(("eps_burn", 0.03),)),
    Case("back-pressure", Hidden(A_e=0.05), 302,
         "back-pressure A_e 0.05 m^2 from the sea-level thrust table, pressure table",
         right=frozenset({"back_pressure"}), needed=frozenset({"back_pressure"}), sizes=(("A_e", 0.05),)),
    Case("headwind", Hidden(wind=(5.0, 20.0)), 303,
         "headwind W(h) = -(5 + 20 (1 - exp(-h/5 km))) m/s",
         right=frozenset({"wind"}), needed=frozenset({"wind"})),
    Case("warm-day", Hidden(warm_dT=8.0), 304,
         "density of an atmosphere 8 K warmer (-2.7 % at 0 km, +3.3 % at 15 km)",
         right=frozenset({"density"}), needed=frozenset({"density"})),
    Case("misalignment", Hidden(delta=MIS), 305,
         "thrust misalignment 0.3 deg from t = 0",
         right=frozenset({"misalignment"}), needed=frozenset({"misalignment"}), sizes=(("delta_thrust", MIS),)),
    Case("earth-rotation", Hidden(rotation=(69.3, 45.0)), 306,
         "Earth rotation, latitude 69.3 N, azimuth 45 deg (Coriolis and centrifugal)",
         right=frozenset({"earth_rotation"}), needed=frozenset({"earth_rotation"})),
    Case("h-bias-drift", Hidden(bias_h=(3.0, 0.15)), 307,
         "altitude bias 3 m + 0.15 m/s t (3 -> 9 m)",
         right=frozenset({"bias_h"}), needed=frozenset({"bias_h"})),
    Case("time-offset", Hidden(tau=0.02), 308,
         "time tags 20 ms late (exact shift)",
         right=frozenset({"time_offset"}), needed=frozenset({"time_offset"}), sizes=(("tau", 0.02),)),
    Case("heavy-start", Hidden(dm0=25.0), 309,
         "start mass 25 kg (1.7 %) above the declared",
         right=frozenset({"start_mass"}), needed=frozenset({"start_mass"}), sizes=(("dm_start", 25.0),)),
    Case("back-pressure+headwind", Hidden(A_e=0.05, wind=(5.0, 20.0)), 310,
         "back-pressure A_e 0.05 m^2 + headwind 5 -> 25 m/s",
         right=frozenset({"back_pressure", "wind"}), needed=frozenset({"back_pressure", "wind"}),
         sizes=(("A_e", 0.05),)),
    Case("misalignment+h-bias-drift", Hidden(delta=MIS, bias_h=(3.0, 0.15)), 311,
         "misalignment 0.3 deg + altitude bias 3 m + 0.15 m/s t",
         right=frozenset({"misalignment", "bias_h"}), needed=frozenset({"misalignment", "bias_h"}),
         sizes=(("delta_thrust", MIS),)),
    Case("clean-200", Hidden(), 200, "clean (seed 200)"),
    Case("clean-201", Hidden(), 201, "clean (seed 201)"),
    Case("clean-202", Hidden(), 202, "clean (seed 202)"),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(203, 208))

#: Cases added after the first run's findings were shared, and kept from the team until the re-run:
#: a check that the fixes made in between generalize rather than fit the published cases.
SEALED = (
    Case("drag-hump", Hidden(drag_bump=(0.08, 1.15, 0.12)), 312,
         "drag hump +0.08 at Mach 1.15 (half-width 0.12) between the CD knots",
         right=frozenset({"transonic_drag", "drag_mach"}), needed=frozenset({"transonic_drag", "drag_mach"})),
    Case("sliver-tailoff", Hidden(tailoff=(0.06, 30.0, 36.0)), 313,
         "thrust and mass flow sag 6 % from 30 s to 36 s (early sliver burn-out)",
         right=HOT, needed=frozenset({"thrust_level", "thrust_profile", "burn_rate"}), sizes=(("eps_burn", 0.03),)),
    Case("tailwind-jet+time-offset", Hidden(jet=(3.0, 30.0, 9000.0, 2500.0), tau=0.02), 314,
         "tailwind 3 m/s surface + sech^2 jet 30 m/s at 9 km, and time tags 20 ms late",
         right=frozenset({"wind", "time_offset"}), needed=frozenset({"wind", "time_offset"}),
         sizes=(("tau", 0.02),)),
)

#: Pairs made on 2026-11-28 after the study's fixes, as a fresh probe of data the diagnosis had not met: new
#: combinations of the truth's effects, new seeds. Two effects that the base model does not show alone on this
#: vehicle (a warm day and Earth rotation at Andoya: both cases above end "nothing found", the base fit at the
#: noise) are allowed but not needed; a drag hump between the knots, found alone only as a rival, likewise.
FRESH = (
    Case("warm-day+time-offset", Hidden(warm_dT=8.0, tau=0.02), 401,
         "warm day +8 K (density -2.7 % at 0 km, +3.3 % at 15 km) and time tags 20 ms late",
         right=frozenset({"density", "time_offset"}), needed=frozenset({"time_offset"}), sizes=(("tau", 0.02),)),
    Case("hot-motor+earth-rotation", Hidden(hot_motor=1.03, rotation=(69.3, 45.0)), 402,
         "thrust curve 3 % faster and higher, and Earth rotation at 69.3 N, azimuth 45 deg",
         right=HOT | {"earth_rotation"}, needed=frozenset({"thrust_level", "thrust_profile", "burn_rate"}),
         sizes=(("eps_burn", 0.03),)),
    Case("heavy-start+headwind", Hidden(dm0=25.0, wind=(5.0, 20.0)), 403,
         "start mass 25 kg above the declared and headwind 5 -> 25 m/s",
         right=frozenset({"start_mass", "wind"}), needed=frozenset({"start_mass", "wind"}),
         needed_each=(frozenset({"start_mass"}), frozenset({"wind"})), sizes=(("dm_start", 25.0),)),
    Case("drag-hump+misalignment", Hidden(drag_bump=(0.08, 1.15, 0.12), delta=MIS), 404,
         "drag hump +0.08 at Mach 1.15 (half-width 0.12) and misalignment 0.3 deg from t = 0",
         right=frozenset({"transonic_drag", "drag_mach", "misalignment"}), needed=frozenset({"misalignment"}),
         sizes=(("delta_thrust", MIS),)),
    Case("back-pressure+warm-day", Hidden(A_e=0.05, warm_dT=8.0), 405,
         "back-pressure A_e 0.05 m^2 (thrust stated at sea level) and a warm day +8 K",
         right=frozenset({"back_pressure", "density"}), needed=frozenset({"back_pressure"}), sizes=(("A_e", 0.05),)),
    Case("sliver-tailoff+h-bias-drift", Hidden(tailoff=(0.06, 30.0, 36.0), bias_h=(3.0, 0.15)), 406,
         "thrust and mass flow sag 6 % from 30 s to 36 s, and altitude bias 3 m + 0.15 m/s t",
         right=HOT | {"bias_h"}, needed=HOT | {"bias_h"},
         needed_each=(HOT, frozenset({"bias_h"}))),
    Case("jet+heavy-start", Hidden(jet=(3.0, 30.0, 9000.0, 2500.0), dm0=25.0), 407,
         "tailwind 3 m/s surface + sech^2 jet 30 m/s at 9 km, and start mass 25 kg above the declared",
         right=frozenset({"wind", "start_mass"}), needed=frozenset({"wind", "start_mass"}),
         needed_each=(frozenset({"wind"}), frozenset({"start_mass"})), sizes=(("dm_start", 25.0),)),
    Case("earth-rotation+h-bias-drift", Hidden(rotation=(28.5, 90.0), bias_h=(-4.0, 0.1)), 408,
         "Earth rotation at 28.5 N launched east, and altitude bias -4 m + 0.1 m/s t",
         right=frozenset({"earth_rotation", "bias_h"}), needed=frozenset({"bias_h"})),
)

ALL = CASES + SEALED + FRESH
BY_NAME = {c.name: c for c in ALL}
