"""The cases of the hybrid sounding-rocket study: Wren-H with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed, and which catalogue families count
as the right answer (``right``: every family in the final model must be one of these, and one of
``needed`` must be there; for a pair, one of each set in ``needed_each``). The answers were decided from
the physics and docs/effects.md's catalogue table when the cases were written, **before any diagnosis
ran**. ``visible`` says whether "nothing found" fails: with ``--sigma estimate`` the harness's rule (the
base chi2/dof inside the noise band) is not the question asked here, so it was decided by "2J >= 25 when
the base model is fitted to the case's noise-free GPS log with the truth's sigmas" (a base fit, not a
diagnosis; measured values in ``MEASURED_2J``, re-measured by ``test_wren_study.py::test_visibility``).

Sizes, relative to Wren-H (60 kg at ignition, 16 kg of N2O, 3.67 kN decaying to 2.94 kN at 9 s, the knee as
the liquid runs out at 9.2-10.5 s, zero thrust at 15.5 s; rail exit at 0.59 s and 25.1 m/s; Mach 1.35 at
10.3 s; apogee 10.18 km above sea level at 44.2 s):

- hot tank: the N2O at 26 C when the valve opens (the static firing's was 20 C: the rocket stood in the sun
  on the pad). Vapour pressure 58 bar instead of 50.6: more oxidiser flow, +8 % thrust, the knee 1 s
  earlier, the same propellant. Right: the thrust families (``thrust_level``, ``thrust_profile``,
  ``mass_flow``) and ``burn_rate`` (a motor on a faster clock, thrust and flow together, is close to this
  physics); needed: ``thrust_level``, ``thrust_profile`` or ``burn_rate``;
- cold tank: the N2O at 14 C (a cool morning): 44 bar, -8.6 % thrust, the knee 1.1 s later. Right and needed
  as the hot tank;
- burn-through: the flight grain's paraffin web ends 16 mm short (outer radius 44 mm, a grain cast for a
  thinner casing liner), at the same launch mass (weighed on the pad): the port reaches the liner from
  6.8 s, the fuel flow falls to the liner's ablation, the O/F ratio climbs and c* with the thrust falls
  (-17 % at 9 s), zero thrust 1.9 s early; the oxidiser flow goes on as before. Right: ``thrust_profile``
  (a thrust shape in time: ``throttle_step`` and the time profiles map there), ``thrust_level`` and
  ``mass_flow`` (thrust and flow errors of the wrong shape alone); needed: ``thrust_profile``. Not
  ``burn_rate``: the motor did not run on a faster clock (the knee is where it was);
- pad hold: the launch waited on the pad and the tank vented 1.5 kg of its 16 kg through the vent valve after
  the weigh-in: lift-off 1.5 kg light **and** the liquid out 1.2 s early (the thrust's knee earlier), the
  thrust before the knee nearly the same. Right: ``start_mass`` (the mass), the thrust families
  (``thrust_profile``, ``thrust_level``, ``mass_flow``: the earlier knee); needed: ``start_mass`` or
  ``thrust_profile`` (either half is the vented oxidiser read from one side);
- headwind: 2 m/s against the flight at 10 m above the pad (a calm morning), growing as ``(z / 10 m)^(1/7)``
  to 1 km, then linearly to a 20 m/s jet core at 9 km above sea level, falling off above it (Gaussian, 3 km). The finned
  rocket flies at zero attack angle **to the air** (its body and thrust along the air-relative velocity; the
  catalogue's wind does the same for a vehicle declared without lift). At 25 m/s off the rail even that
  light surface wind turns the rocket 4 deg into it, and the flight goes 1.9 times as far downrange (4.1 km
  at apogee for 2.1 km) and 620 m lower. (With 4 m/s at 10 m it went 2.6 times as far, and ``rocketid``
  refused the data before any fit: "channel 'x' (downrange) looks in feet"; the unit check's tolerance
  takes a factor 2.6 for 3.28.) Right: ``wind``;
- rail angle: the rail stood at 83.5 deg, not the declared 85 (the inclinometer was read on a sagging rail):
  the rail-exit flight-path angle 1.5 deg low. Written as **out of the catalogue** (no entry changed a declared
  initial state; a thrust misalignment or a surface wind would turn the path, not start it turned): only an
  honest verdict passed. The first run called a surface wind explained, and the catalogue gained
  ``start_angle`` (a declared moving start's flight-path angle corrected, 2026-11-26) **because of this
  case**: the case is now scored with ``start_angle`` as the answer, and it is no longer blind evidence for
  that entry -- only for the others not stealing it;
- geoid: the GPS altitude is height above the WGS-84 ellipsoid, which lies 25 m above the geoid (sea level)
  at the site, and the team took it for altitude above sea level: every altitude 25 m low (bias -25 m).
  Right: ``bias_h``;
- GPS latency: the receiver tags each fix 0.2 s after the instant it describes (its navigation filter's
  latency): every channel's time tags 0.2 s late (two samples). Right: ``time_offset``;
- nose ballast: 1.5 kg of ballast added in the nose after the weigh-in (the stability margin was short):
  launch mass 61.5 kg. Right: ``start_mass``; also ``start_speed`` (added 2026-11-26 with the entry, from the
  truth's physics: the team's rail-exit speed is worked out for 60 kg, and the heavier rocket leaves the rail
  0.3 m/s slower -- a real error of the declared start);
- hot day: the air 15 K warmer than the 1976 standard at every altitude, hydrostatic from the standard
  sea-level pressure (a desert summer afternoon: density -4.4 % at the pad, +1 % at 10 km; speed of sound
  +2.6-3.3 %, so the Mach numbers lower). Right: ``density`` (its ``temperature`` shape included);
- base drag: the power-off base drag of the blunt base once the jet stops filling it: ``dCD = 0.10 +
  0.08 exp(-((M - 1.05)/0.3)^2 / 2)`` (0.10 subsonic, 0.18 at Mach 1.05), faded in as the chamber pressure
  falls from 4 to 2 bar in the tail-off (14.2-17.1 s; the thrust is zero from 15.5 s). Right: ``base_drag``
  (the catalogue's power-off increment and its Mach shapes); the drag families that only refine CD(M)
  (``transonic_drag``, ``drag_mach``) are not: every Mach number is flown both powered and coasting, and
  a Mach shape would tell the team its table is too coarse, the wrong conclusion;
- two pairs: a summer launch (hot tank + hot day), and the GPS's two errors (geoid + latency); four clean
  seeds (nothing to find);
- ``FRESH``: eight more pairs (seeds 330-337), made on 2026-11-28 as a probe on data nobody had fitted, with
  signs, sizes and mates the first cases do not have: a cool tank (16 C) with 2 kg of ballast, a tailwind with
  the geoid the other way (+18 m), a steep rail (86.5 deg) on a cold day (-10 K), time tags 0.15 s early on a
  warm day (+10 K), a web 13 mm short with the altitude 15 m low, the base drag with 0.1 s of latency, 1 kg
  vented with a light tailwind, a warm tank (23 C) on a shallow rail (84 deg). Their answers, by the same
  rules as above, were written before any diagnosis ran.

Every case has the regime's data: GPS at 10 Hz from T+2 s to 44 s (apogee), 2 % of the fixes lost, noise
2.5 m, 7.5 m, 0.25 m/s (never stated); the diagnosis runs with ``--sigma estimate`` on the whole horizon
(the states at rail exit are declared).
"""

from __future__ import annotations

import math

from study_harness import Case, one, pair

from .truth import Hidden

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow"})
MOTOR = THRUST | {"burn_rate"}
MOTOR_NEEDED = frozenset({"thrust_level", "thrust_profile", "burn_rate"})
HOT_TANK = 299.15                    # K (26 C); the static firing's 293.15 K
COLD_TANK = 287.15                   # K (14 C)
THIN_WEB = 0.044                     # m, paraffin outer radius (declared motor: 0.060)
VENTED = 1.5                         # kg of N2O lost on the pad
HEADWIND = (-2.0, -20.0)             # m/s at 10 m above the pad, at the 9 km jet core; + downrange
RAIL_TRUE_DEG = 83.5                 # declared 85
GEOID = -25.0                        # m, GPS altitude bias
LATENCY = 0.2                        # s
BALLAST = 1.5                        # kg
DT_HOT = 15.0                        # K

CASES = (
    Case("hot-tank", Hidden(tank_temperature=HOT_TANK), 301,
         "N2O at 26 C (static firing 20 C): 58 bar, +8 % thrust, the liquid out 1 s early, same propellant",
         right=MOTOR, needed=MOTOR_NEEDED, visible=True),
    Case("cold-tank", Hidden(tank_temperature=COLD_TANK), 302,
         "N2O at 14 C: 44 bar, -8.6 % thrust, the liquid out 1.1 s late, same propellant",
         right=MOTOR, needed=MOTOR_NEEDED, visible=True),
    Case("burn-through", Hidden(grain_radius=THIN_WEB), 303,
         "paraffin web 16 mm short: the port reaches the liner from 6.8 s, thrust -17 % at 9 s, zero thrust 1.9 s "
         "early, the oxidiser flow as before",
         right=THRUST, needed=frozenset({"thrust_profile"}), visible=True),
    Case("pad-hold", Hidden(vented=VENTED), 304,
         "1.5 kg of N2O vented on the pad after the weigh-in: lift-off 1.5 kg light, the liquid out 1.2 s early",
         right=THRUST | {"start_mass"}, needed=frozenset({"start_mass", "thrust_profile"}),
         sizes=(("dm_start", -VENTED),), visible=True),
    Case("headwind", Hidden(wind=HEADWIND), 305,
         "headwind 2 m/s at 10 m, 20 m/s at a 9 km jet core; the rocket flies at zero attack angle to the air",
         right=frozenset({"wind"}), needed=frozenset({"wind"}), visible=True),
    Case("rail-angle", Hidden(elevation_deg=RAIL_TRUE_DEG), 306,
         "rail at 83.5 deg, declared 85: the flight starts 1.5 deg lower (start_angle, added for this case)",
         right=frozenset({"start_angle"}), needed=frozenset({"start_angle"}),
         sizes=(("dgamma_start", math.radians(RAIL_TRUE_DEG - 85.0)),), visible=True),
    Case("geoid", Hidden(bias_h=GEOID), 307,
         "GPS altitude above the ellipsoid taken for above sea level: 25 m low",
         right=frozenset({"bias_h"}), needed=frozenset({"bias_h"}), sizes=(("b_h", GEOID),), visible=True),
    Case("gps-latency", Hidden(tau=LATENCY), 308,
         "GPS time tags 0.2 s late (the receiver's solution latency), every channel",
         right=frozenset({"time_offset"}), needed=frozenset({"time_offset"}), sizes=(("tau", LATENCY),),
         visible=True),
    Case("nose-ballast", Hidden(dm_payload=BALLAST), 309,
         "1.5 kg of nose ballast added after the weigh-in (61.5 kg at ignition)",
         right=frozenset({"start_mass", "start_speed"}), needed=frozenset({"start_mass"}), sizes=(("dm_start", BALLAST),),
         visible=True),
    Case("hot-day", Hidden(dT=DT_HOT), 310,
         "air 15 K warmer than the 1976 standard, hydrostatic (density -4.4 % at the pad, +1 % at 10 km)",
         right=frozenset({"density"}), needed=frozenset({"density"}), sizes=(("dT_air", DT_HOT),), visible=True),
    Case("base-drag", Hidden(base_drag=True), 311,
         "power-off base drag once the jet stops filling the base: dCD 0.10 subsonic, 0.18 at Mach 1.05, faded in "
         "over 14.2-17.1 s (chamber 4 -> 2 bar)",
         right=frozenset({"base_drag"}), needed=frozenset({"base_drag"}), visible=True),
    Case("hot-tank+hot-day", Hidden(tank_temperature=HOT_TANK, dT=DT_HOT), 312,
         "a summer launch: N2O at 26 C + air 15 K warmer",
         right=MOTOR | {"density"}, needed=MOTOR_NEEDED | {"density"},
         needed_each=(MOTOR_NEEDED, frozenset({"density"})), sizes=(("dT_air", DT_HOT),), visible=True),
    Case("geoid+gps-latency", Hidden(bias_h=GEOID, tau=LATENCY), 313,
         "GPS altitude 25 m low (ellipsoid) + time tags 0.2 s late",
         right=frozenset({"bias_h", "time_offset"}), needed=frozenset({"bias_h", "time_offset"}),
         needed_each=(frozenset({"bias_h"}), frozenset({"time_offset"})),
         sizes=(("b_h", GEOID), ("tau", LATENCY)), visible=True),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(320, 324))

#: 2J of the base model fitted to each case's noise-free GPS log (seed's fixes) with the truth's sigmas
#: (measured when the cases were written, before any diagnosis; ``visible`` is 2J >= 25).
MEASURED_2J = {"hot-tank": 9.543e5, "cold-tank": 6.257e5, "burn-through": 5310.0, "pad-hold": 7.977e4,
               "headwind": 8.373e7, "rail-angle": 8.138e6, "geoid": 3424.0, "gps-latency": 9.827e4,
               "nose-ballast": 5.989e4, "hot-day": 650.7, "base-drag": 4.324e4, "hot-tank+hot-day": 9.818e5,
               "geoid+gps-latency": 1.135e5, "clean-320": 0.1865,
               # the fresh pairs (measured 2026-11-28 by the same fit, before any diagnosis ran on them)
               "cool-tank+ballast": 6.367e5, "tailwind+geoid-up": 5.49e7, "steep-rail+cold-day": 8.51e6,
               "early-tags+warm-day": 7.669e4, "short-web+geoid": 1513.0, "base-drag+latency": 2.707e4,
               "vent+tailwind": 2.119e7, "warm-tank+shallow-rail": 3.274e6}
VISIBLE_2J = 25.0


#: Eight more pairs, made on 2026-11-28 as a probe on data nobody had fitted (module notes), seeds 330-337; every
#: one measured visible (MEASURED_2J).
FRESH = (
    pair("cool-tank+ballast", Hidden(tank_temperature=289.15, dm_payload=2.0), 330,
         "N2O at 16 C (about -5 % thrust, the liquid out later) + 2 kg of ballast after the weigh-in", MOTOR_NEEDED,
         one("start_mass"), sizes=(("dm_start", 2.0),), also=frozenset({"mass_flow", "start_speed"}), visible=True),
    pair("tailwind+geoid-up", Hidden(wind=(1.5, 15.0), bias_h=18.0), 331,
         "tailwind 1.5 m/s at 10 m, 15 m/s at the 9 km jet core + GPS altitude 18 m high", one("wind"), one("bias_h"),
         sizes=(("b_h", 18.0),), visible=True),
    pair("steep-rail+cold-day", Hidden(elevation_deg=86.5, dT=-10.0), 332,
         "rail at 86.5 deg, declared 85 + air 10 K colder than the standard", one("start_angle"), one("density"),
         sizes=(("dgamma_start", math.radians(1.5)), ("dT_air", -10.0)), visible=True),
    pair("early-tags+warm-day", Hidden(tau=-0.15, dT=10.0), 333,
         "GPS time tags 0.15 s early + air 10 K warmer than the standard", one("time_offset"), one("density"),
         sizes=(("tau", -0.15), ("dT_air", 10.0)), visible=True),
    pair("short-web+geoid", Hidden(grain_radius=0.047, bias_h=-15.0), 334,
         "paraffin web 13 mm short (the port at the liner late in the burn) + GPS altitude 15 m low",
         one("thrust_profile"), one("bias_h"), sizes=(("b_h", -15.0),),
         also=frozenset({"thrust_level", "mass_flow"}), visible=True),
    pair("base-drag+latency", Hidden(base_drag=True, tau=0.1), 335,
         "power-off base drag in the tail-off + GPS time tags 0.1 s late", one("base_drag"), one("time_offset"),
         sizes=(("tau", 0.1),), visible=True),
    pair("vent+tailwind", Hidden(vented=1.0, wind=(1.0, 10.0)), 336,
         "1 kg of N2O vented on the pad + tailwind 1 m/s at 10 m, 10 m/s at the jet core",
         frozenset({"start_mass", "thrust_profile"}), one("wind"), also=frozenset({"thrust_level", "mass_flow"}),
         visible=True),
    pair("warm-tank+shallow-rail", Hidden(tank_temperature=296.15, elevation_deg=84.0), 337,
         "N2O at 23 C (about +4 % thrust, the liquid out earlier) + rail at 84 deg, declared 85", MOTOR_NEEDED,
         one("start_angle"), sizes=(("dgamma_start", math.radians(-1.0)),), also=frozenset({"mass_flow"}),
         visible=True),
)

ALL = CASES + FRESH
BY_NAME = {c.name: c for c in ALL}
