"""The cases of the sounding-rocket study: Tern-2 with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed, and which catalogue
families count as the right answer (``right``: every family in the final model must be one of
these, and one of ``needed`` must be there; for a pair, one of each set in ``needed_each``).
The answers were decided when the cases were written, before any diagnosis ran.

Sizes, relative to Tern-2 (810 kg at ignition, 0.38 m body, sea-level thrust table 88 -> 114 ->
98 kN with a tail-off to 0 at 10.25 s, rail exit at 0.5 s and 37.6 m/s, burn-out at 6.9 km and
Mach 3.86, the coast to 45.6 km and Mach 1.62 by 60 s at zero attack angle):

- cold motor: a grain conditioned cold (a winter launch), the burn 3 % slower and weaker,
  ``P(t) = 0.97 P_tab(0.97 t)``, the mass flow on the same clock (the same propellant and total
  impulse, burn-out 0.32 s later). Right: the thrust families (``thrust_level``,
  ``thrust_profile``, ``mass_flow``) and ``burn_rate`` (the motor on another clock, its own
  physics); needed: ``thrust_level``, ``thrust_profile`` or ``burn_rate``;
- back-pressure: the table is a sea-level static firing; the truth thrust is
  ``P_tab + A_e (p_sl - p_a(h))`` with a 0.30 m nozzle exit (``A_e`` 0.0707 m^2) while the jet
  flows (faded with the thrust below 50 kN in the tail-off): 0 at the rail, +2.8 kN (2.7 %) at
  4 km, +3.4 kN at 5.1 km where the fade begins (8.8 s). Right: ``back_pressure`` and, as in the
  air-launch study, the thrust families that carry a thrust error at the stated mass flow
  (``thrust_level``, ``thrust_profile``); not ``burn_rate`` (the mass flow is the table's) nor
  ``mass_flow``;
- headwind: a realistic launch-day wind against the flight: 5 m/s at 10 m, growing as
  ``(h / 10 m)^(1/7)`` to 9.7 m/s at 1 km, then linearly to 20 m/s at an 11 km jet core, halving
  5 km above it. The fin-stabilized rocket weathercocks into it: its body turns toward the
  airflow as a lightly damped pendulum of its static margin (truth.py), the thrust along the body,
  the fins' normal force across the airflow, the drag against it -- 7.4 deg of incidence at rail
  exit, where the airspeed is low, the body 3.5 deg off the ground path at 2 s. Right: ``wind``;
- cold day: the 1976 temperature profile 15 K colder over the whole column, the ground pressure
  standard, pressure through the hydrostatic equation (density +5.5 % at the ground, +3.1 % at
  4 km, -1.5 % at 10 km, -12 % at 20 km, -26 % at 35 km); the speed of sound 2.6-3.5 % lower, so
  the Mach number higher. Right: ``density`` (the catalogue's atmosphere family, its
  ``temperature`` shape included);
- heavy payload: launch mass 20 kg (2.5 %) above the declared 810 kg (a payload heavier than
  its paperwork). Right: ``start_mass``;
- altimeter bias: the radar's altitude 10 m high (a survey error of the radar's height), constant.
  Right: ``bias_h``;
- speed scale: the radar's speed 0.2 % long. Right: ``scale_v``;
- time offset: the radar's time tags 20 ms late (0.4 of a sample), an exact shift. Right:
  ``time_offset``;
- supersonic drag: the true CD 8 % higher above Mach 2 (a smooth step
  ``CD_tab (1 + 0.08 (1 + tanh((M - 2)/0.1))/2)``, centred on the table's knot 2.0). The
  table's own knots above Mach 2 take the 8 % almost exactly; what is left is the step's shape
  between the knots 1.6, 2.0 and 2.5, passed in a fraction of a second under thrust and again in
  the last ten seconds of the coast. Right: the drag families ``transonic_drag`` and
  ``drag_mach``; "nothing found" passes when the base fit shows nothing (the harness's rule).
  Measured once the cases were written: the base fit takes it to 2J = 2.9 on noise-free data, so
  "nothing found" is the expected answer (``test_what_the_drag_table_absorbs``);
- base drag at burn-out: power-off drag higher than power-on, ``dCD = 0.2 / M`` (0.051 at
  Mach 3.9, 0.067 at Mach 3, 0.1 at Mach 2) switched on as the jet stops filling the base (faded
  in as the thrust falls below 50 kN in the tail-off). **Out of the catalogue**: the drag then
  depends on the motor's state, not on the Mach number alone; the base model's CD table is
  already free in Mach, and the catalogue's drag shapes (``transonic_drag``, ``drag_mach``, the
  located hump) only add Mach resolution, which is not the missing physics -- a Mach shape that
  reached the noise would tell a user the table is too coarse, the wrong conclusion. No family is
  right: only an honest verdict (anything but "explained") passes. (Measured afterwards: the base
  fit leaves 2J = 7.4e4 on noise-free data, so the effect is visible);
- Earth rotation: launched at 37.84 N (Wallops Island) on azimuth 120 deg, Coriolis and
  centrifugal accelerations in three dimensions (the flight drifts out of its plane). Right:
  ``earth_rotation`` (the catalogue's fixed 28.5 N, east: its ``k_rot`` is not the truth's 1, so
  no size is compared);
- three pairs: a winter launch (cold motor + cold day), headwind + altimeter bias, heavy
  payload + time offset; six clean seeds (nothing to find).
"""

from __future__ import annotations

from study_harness import Case, pair

from .truth import Hidden

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow"})
MOTOR = THRUST | {"burn_rate"}
MOTOR_NEEDED = frozenset({"thrust_level", "thrust_profile", "burn_rate"})
DRAG = frozenset({"transonic_drag", "drag_mach"})
NOZZLE = frozenset({"back_pressure", "thrust_level", "thrust_profile"})   # a sea-level thrust table's back-pressure
K_COLD = 0.97
A_EXIT = 0.0707                      # m^2, a 0.30 m nozzle exit
WIND = (-5.0, -20.0)                 # m/s at 10 m and at the 11 km core, + downrange: a headwind
DT_COLD = -15.0
DM0 = 20.0
BIAS_H = 10.0
K_V = 0.002
TAU = 0.02
DRAG_STEP = (0.08, 2.0, 0.1)
BASE_DRAG = 0.2
WALLOPS = (37.84, 120.0)


CASES = (
    Case("cold-motor", Hidden(motor_clock=K_COLD), 601,
         "cold grain: thrust curve 3 % slower and weaker, P(t) = 0.97 P_tab(0.97 t), mass flow with it",
         right=MOTOR, needed=MOTOR_NEEDED, sizes=(("eps_burn", K_COLD - 1.0),)),
    Case("back-pressure", Hidden(A_e=A_EXIT), 602,
         "sea-level thrust table, truth P_tab + A_e (p_sl - p_a(h)), A_e 0.0707 m^2 (+3 % at 4 km)",
         right=frozenset({"back_pressure", "thrust_level", "thrust_profile"}),
         needed=frozenset({"back_pressure", "thrust_level", "thrust_profile"}), sizes=(("A_e", A_EXIT),)),
    Case("headwind", Hidden(wind=WIND), 603,
         "headwind 5 m/s at 10 m, 9.7 m/s at 1 km, 20 m/s at 11 km; the rocket weathercocks into it",
         right=frozenset({"wind"}), needed=frozenset({"wind"})),
    Case("cold-day", Hidden(dT=DT_COLD), 604,
         "atmosphere 15 K colder over the column, hydrostatic (density +5.5 % at the ground, -9 % at 20 km; "
         "Mach +2.7 %)",
         right=frozenset({"density"}), needed=frozenset({"density"})),
    Case("heavy-payload", Hidden(dm0=DM0), 605,
         "launch mass 20 kg (2.5 %) above the declared 810 kg",
         right=frozenset({"start_mass"}), needed=frozenset({"start_mass"}), sizes=(("dm_start", DM0),)),
    Case("h-bias", Hidden(bias_h=BIAS_H), 606,
         "radar altitude 10 m high",
         right=frozenset({"bias_h"}), needed=frozenset({"bias_h"}), sizes=(("b_h", BIAS_H),)),
    Case("v-scale", Hidden(scale_v=K_V), 607,
         "radar speed 0.2 % long",
         right=frozenset({"scale_v"}), needed=frozenset({"scale_v"}), sizes=(("k_v", K_V),)),
    Case("time-offset", Hidden(tau=TAU), 608,
         "radar time tags 20 ms late (exact shift)",
         right=frozenset({"time_offset"}), needed=frozenset({"time_offset"}), sizes=(("tau", TAU),)),
    Case("supersonic-drag", Hidden(drag_step=DRAG_STEP), 609,
         "CD 8 % higher above Mach 2 (smooth step of half-width 0.1 on the knot 2.0)",
         right=DRAG, needed=DRAG),
    # out of the catalogue when the study was written; base_drag (a power-off drag increment, and its Mach-shaped
    # refinement) was added after the study's runs called this case explained by a density profile (2026-11-26):
    # right since then, and no longer blind evidence
    Case("base-drag", Hidden(base_drag=BASE_DRAG), 610,
         "power-off base drag dCD = 0.2/M (0.05 at Mach 3.9) from burn-out: drag depends on the motor's state",
         right=frozenset({"base_drag"}), needed=frozenset({"base_drag"})),
    Case("earth-rotation", Hidden(rotation=WALLOPS), 611,
         "Earth rotation, 37.84 N, azimuth 120 deg (Coriolis and centrifugal, 3-D)",
         right=frozenset({"earth_rotation"}), needed=frozenset({"earth_rotation"})),
    Case("cold-motor+cold-day", Hidden(motor_clock=K_COLD, dT=DT_COLD), 612,
         "a winter launch: cold grain (k 0.97) + atmosphere 15 K colder",
         right=MOTOR | {"density"}, needed=MOTOR_NEEDED | {"density"},
         needed_each=(MOTOR_NEEDED, frozenset({"density"})), sizes=(("eps_burn", K_COLD - 1.0),)),
    pair("headwind+h-bias", Hidden(wind=WIND, bias_h=BIAS_H), 613,
          "headwind (5 m/s at 10 m, 20 m/s at 11 km) + radar altitude 10 m high",
          frozenset({"wind"}), frozenset({"bias_h"}), sizes=(("b_h", BIAS_H),)),
    pair("heavy-payload+time-offset", Hidden(dm0=DM0, tau=TAU), 614,
          "launch mass 20 kg above the declared + radar time tags 20 ms late",
          frozenset({"start_mass"}), frozenset({"time_offset"}), sizes=(("dm_start", DM0), ("tau", TAU))),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(700, 706))

#: Pairs made on 2026-11-28 as a fresh probe of combinations the diagnosis had not met, new seeds; the supersonic
#: drag rise, which the base model does not show alone (its case above ends "nothing found" at the noise), is
#: allowed but not needed (docs/effects.md, "Fresh pairs on Tern-2").
FRESH = (
    pair("heavy-payload+headwind", Hidden(dm0=DM0, wind=WIND), 801,
          "launch mass 20 kg above the declared + headwind (5 m/s at 10 m, 20 m/s at 11 km)",
          frozenset({"start_mass"}), frozenset({"wind"}), sizes=(("dm_start", DM0),)),
    pair("back-pressure+h-bias", Hidden(A_e=A_EXIT, bias_h=BIAS_H), 802,
          "sea-level thrust table with A_e 0.0707 m^2 + radar altitude 10 m high",
          NOZZLE, frozenset({"bias_h"}), sizes=(("A_e", A_EXIT), ("b_h", BIAS_H))),
    Case("cold-motor+v-scale", Hidden(motor_clock=K_COLD, scale_v=K_V), 803,
         "cold grain (k 0.97) + radar speed 0.2 % long",
         right=MOTOR | {"scale_v"}, needed=MOTOR_NEEDED | {"scale_v"},
         needed_each=(MOTOR_NEEDED, frozenset({"scale_v"})), sizes=(("eps_burn", K_COLD - 1.0), ("k_v", K_V))),
    Case("supersonic-drag+time-offset", Hidden(drag_step=DRAG_STEP, tau=TAU), 804,
         "CD 8 % higher above Mach 2 + radar time tags 20 ms late",
         right=DRAG | {"time_offset"}, needed=frozenset({"time_offset"}), needed_each=(frozenset({"time_offset"}),),
         sizes=(("tau", TAU),)),
    pair("cold-day+heavy-payload", Hidden(dT=DT_COLD, dm0=DM0), 805,
          "atmosphere 15 K colder + launch mass 20 kg above the declared",
          frozenset({"density"}), frozenset({"start_mass"}), sizes=(("dm_start", DM0),)),
    pair("earth-rotation+h-bias", Hidden(rotation=WALLOPS, bias_h=BIAS_H), 806,
          "Earth rotation (37.84 N, azimuth 120 deg) + radar altitude 10 m high",
          frozenset({"earth_rotation"}), frozenset({"bias_h"}), sizes=(("b_h", BIAS_H),)),
    pair("base-drag+headwind", Hidden(base_drag=BASE_DRAG, wind=WIND), 807,
          "power-off base drag 0.2/M from burn-out + headwind (5 m/s at 10 m, 20 m/s at 11 km)",
          frozenset({"base_drag"}), frozenset({"wind"})),
    pair("back-pressure+cold-day", Hidden(A_e=A_EXIT, dT=DT_COLD), 808,
          "sea-level thrust table with A_e 0.0707 m^2 + atmosphere 15 K colder",
          NOZZLE, frozenset({"density"}), sizes=(("A_e", A_EXIT),)),
)

ALL = CASES + FRESH
BY_NAME = {c.name: c for c in ALL}
