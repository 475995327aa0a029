"""The cases of the air-launch study: Osprey-A with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed, and which catalogue
families count as the right answer (``right``: every family in the final model must be one of
these, and one of ``needed`` must be there; for a pair, one of each set in ``needed_each``).
Sizes, relative to Osprey-A (19.5 t at ignition, sea-level thrust table 540 -> 585 -> 470 kN,
ignition at 11.8 km and Mach 0.80, burn-out at 68 s near 54.5 km and Mach 8.9, wing area 12 m^2):

- hot motor: thrust curve 3 % higher and 3 % faster, ``P(t) = 1.03 P_tab(1.03 t)``, the mass flow
  with it (a warm grain);
- back-pressure: the table is a sea-level static firing, the truth thrust
  ``P_tab + A_e (p_sl - p_a(h))`` with ``A_e`` 0.9 m^2 (a 1.07 m exit): +73 kN at ignition
  altitude, +91 kN in vacuum -- nearly a constant 13-19 % increase, since ``p_a`` is already
  small at 12 km; whether this can be told from a thrust level is part of the question, so both
  families count as right;
- jet stream: a 40 m/s headwind peaked at 12 km, half of it 3 km below the core and 4.5 km
  above (it decays more slowly aloft); the vehicle starts inside the core;
- cold column: the 1976 temperature profile 10 K colder from the ground up, pressure through the
  hydrostatic equation (density +3.6 % at the ground, -2.1 % at 11.8 km, -8.0 % at 20 km,
  -15 % at 30 km, -24 % at 50 km); the speed of sound falls with the temperature (Mach 2.4 %
  higher);
- misalignment 0.3 deg from ignition;
- altimeter bias 15 m, constant;
- speed-channel scale error +0.3 %;
- Earth rotation: launched due east at 28.5 N (Coriolis and centrifugal);
- time tags 30 ms late (0.6 of a sample at 20 Hz);
- start mass 1.5 % (292.5 kg) above the declared 19 500 kg;
- a transonic drag hump +0.15 at Mach 1.1 (14 % of the drag there, on the body's cross-section),
  half-height half-width 0.15, between the table's knots 1.0 and 1.25, passed in the first
  seconds after ignition;
- three pairs; six clean seeds;
- ``FRESH``: eight more pairs (seeds 415-422), made on 2026-11-28 with signs, sizes and sites the first cases
  do not have.
"""

from __future__ import annotations

import math

from study_harness import Case, one, pair

from .truth import Hidden

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow"})
# burn_rate (thrust and mass flow together on a faster motor clock, the hot motor's own physics) was added to the
# catalogue after the study was written (2026-11-26): right for the hot motor, whose truth is that change
HOT = THRUST | {"burn_rate"}
JET = (-40.0, 12_000.0, 3_000.0, 4_500.0)
MIS = math.radians(0.3)
DM0 = 292.5


CASES = (
    Case("hot-motor", Hidden(hot_motor=1.03), 401,
         "thrust curve 3 % faster and higher, P(t) = 1.03 P_tab(1.03 t), mass flow with it",
         right=HOT, needed=frozenset({"thrust_level", "thrust_profile", "burn_rate"}), sizes=(("eps_burn", 0.03),)),
    Case("back-pressure", Hidden(A_e=0.9), 402,
         "sea-level thrust table, truth P_tab + A_e (p_sl - p_a(h)), A_e 0.9 m^2 (+73 kN at 11.8 km)",
         right=frozenset({"back_pressure", "thrust_level", "thrust_profile"}),
         needed=frozenset({"back_pressure", "thrust_level", "thrust_profile"}), sizes=(("A_e", 0.9),)),
    Case("jet-stream", Hidden(jet=JET), 403,
         "headwind jet 40 m/s at 12 km (half 3 km below, 4.5 km above), start inside it",
         right=frozenset({"wind"}), needed=frozenset({"wind"})),
    Case("cold-column", Hidden(dT=-10.0), 404,
         "atmosphere 10 K colder over the column, hydrostatic (density -2 % at 12 km, -15 % at 30 km; Mach +2.4 %)",
         right=frozenset({"density"}), needed=frozenset({"density"})),
    Case("misalignment", Hidden(delta=MIS), 405,
         "thrust misalignment 0.3 deg from ignition",
         right=frozenset({"misalignment"}), needed=frozenset({"misalignment"}), sizes=(("delta_thrust", MIS),)),
    Case("h-bias", Hidden(bias_h=(15.0, 0.0)), 406,
         "altimeter bias 15 m",
         right=frozenset({"bias_h"}), needed=frozenset({"bias_h"}), sizes=(("b_h", 15.0),)),
    Case("v-scale", Hidden(scale_v=0.003), 407,
         "speed channel reads 0.3 % long",
         right=frozenset({"scale_v"}), needed=frozenset({"scale_v"}), sizes=(("k_v", 0.003),)),
    Case("earth-rotation", Hidden(rotation=(28.5, 90.0)), 408,
         "Earth rotation, 28.5 N, launched due east (Coriolis and centrifugal)",
         right=frozenset({"earth_rotation"}), needed=frozenset({"earth_rotation"}), sizes=(("k_rot", 1.0),)),
    Case("time-offset", Hidden(tau=0.03), 409,
         "time tags 30 ms late (exact shift)",
         right=frozenset({"time_offset"}), needed=frozenset({"time_offset"}), sizes=(("tau", 0.03),)),
    Case("heavy-start", Hidden(dm0=DM0), 410,
         "start mass 292.5 kg (1.5 %) above the declared 19 500 kg",
         right=frozenset({"start_mass"}), needed=frozenset({"start_mass"}), sizes=(("dm_start", DM0),)),
    Case("drag-hump", Hidden(drag_bump=(0.15, 1.1, 0.15)), 411,
         "drag hump +0.15 (14 %) at Mach 1.1 (half-width 0.15), between the CD knots 1.0 and 1.25",
         right=frozenset({"transonic_drag", "drag_mach"}), needed=frozenset({"transonic_drag", "drag_mach"})),
    Case("jet-stream+h-bias", Hidden(jet=JET, bias_h=(15.0, 0.0)), 412,
         "headwind jet 40 m/s at 12 km + altimeter bias 15 m",
         right=frozenset({"wind", "bias_h"}), needed=frozenset({"wind", "bias_h"}),
         needed_each=(frozenset({"wind"}), frozenset({"bias_h"})), sizes=(("b_h", 15.0),)),
    Case("hot-motor+misalignment", Hidden(hot_motor=1.03, delta=MIS), 413,
         "hot motor (k 1.03) + misalignment 0.3 deg",
         right=HOT | {"misalignment"},
         needed=frozenset({"thrust_level", "thrust_profile", "burn_rate", "misalignment"}),
         needed_each=(frozenset({"thrust_level", "thrust_profile", "burn_rate"}), frozenset({"misalignment"})),
         sizes=(("eps_burn", 0.03), ("delta_thrust", MIS))),
    Case("cold-column+v-scale", Hidden(dT=-10.0, scale_v=0.003), 414,
         "atmosphere 10 K colder + speed channel 0.3 % long",
         right=frozenset({"density", "scale_v"}), needed=frozenset({"density", "scale_v"}),
         needed_each=(frozenset({"density"}), frozenset({"scale_v"})), sizes=(("k_v", 0.003),)),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(500, 506))


TAILJET = (30.0, 14_000.0, 2_500.0, 5_000.0)
MIS_NEG = math.radians(-0.25)
MIS_BIG = math.radians(0.35)
#: Eight more pairs, made on 2026-11-28 as a probe on data nobody had fitted: signs, sizes and sites the study's
#: first cases do not have (a light start, a tailwind jet above the start, a negative misalignment, a drifting
#: altimeter, a cool motor, a warm column, a westward launch at 35 N), seeds 415-422.
FRESH = (
    pair("light-start+tailwind-jet", Hidden(dm0=-250.0, jet=TAILJET), 415,
          "start mass 250 kg (1.3 %) below the declared + tailwind jet 30 m/s at 14 km", one("start_mass"),
          one("wind"), sizes=(("dm_start", -250.0),)),
    pair("misalignment-down+h-bias-drift", Hidden(delta=MIS_NEG, bias_h=(-10.0, 0.2)), 416,
          "thrust misalignment -0.25 deg + altimeter -10 m + 0.2 m/s t", one("misalignment"), one("bias_h"),
          sizes=(("delta_thrust", MIS_NEG),)),
    pair("cold-column+drag-hump", Hidden(dT=-8.0, drag_bump=(0.12, 1.05, 0.12)), 417,
          "atmosphere 8 K colder + drag hump +0.12 at Mach 1.05 (half-width 0.12)", one("density"),
          frozenset({"transonic_drag", "drag_mach"})),
    pair("time-offset+jet-stream", Hidden(tau=0.04, jet=JET), 418,
          "time tags 40 ms late + headwind jet 40 m/s at 12 km", one("time_offset"), one("wind"),
          sizes=(("tau", 0.04),)),
    pair("westward-rotation+v-scale", Hidden(rotation=(35.0, 270.0), scale_v=-0.004), 419,
          "Earth rotation, 35 N launched due west + speed channel 0.4 % short", one("earth_rotation"),
          one("scale_v"), sizes=(("k_v", -0.004),)),
    pair("cool-motor+h-bias", Hidden(hot_motor=0.98, bias_h=(-12.0, 0.0)), 420,
          "thrust curve 2 % lower and slower, P(t) = 0.98 P_tab(0.98 t) + altimeter -12 m", HOT, one("bias_h"),
          sizes=(("eps_burn", -0.02), ("b_h", -12.0))),
    pair("warm-column+misalignment", Hidden(dT=12.0, delta=MIS_BIG), 421,
          "atmosphere 12 K warmer + thrust misalignment 0.35 deg", one("density"), one("misalignment"),
          sizes=(("delta_thrust", MIS_BIG),)),
    pair("back-pressure+time-offset", Hidden(A_e=0.6, tau=-0.03), 422,
          "sea-level thrust table, truth P_tab + A_e (p_sl - p_a(h)) with A_e 0.6 m^2 + time tags 30 ms early",
          frozenset({"back_pressure", "thrust_level", "thrust_profile"}), one("time_offset"),
          sizes=(("A_e", 0.6), ("tau", -0.03))),
)

ALL = CASES + FRESH
BY_NAME = {c.name: c for c in ALL}
