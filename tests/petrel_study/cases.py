"""The cases of the high-site study: Petrel-V with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed (500-530), and which catalogue
families count as the right answer (``right``: every family in the final model must be one of these;
``needed``: one of them must be there; ``needed_each``: for a pair, one of each set). Sizes, relative
to Petrel-V (2.4 t, thrust 60 -> 50 kN at sea level, 0.6 m, from 1420 m to 31 km, Mach 0.09 -> 3.4):

- blowdown: the thrust falls off faster than the acceptance test's table, linearly in the propellant
  used, -6 % at cutoff, the mass flow with it (same Isp);
- vacuum-nozzle: the table is the sea-level thrust, the nozzle's exit area 0.06 m^2: +0.96 kN at the
  rail exit (1420 m), +6 kN (12 %) at cutoff altitude;
- cold-day: the column 10 K colder than the standard, hydrostatic from the standard's sea-level
  pressure (density +3.1 % at the pad, -1.5 % at 11 km, -15 % at 30 km), speed of sound standard;
- jet-wind: a tailwind of 4 m/s at the ground growing logarithmically to 8 m/s 1 km above the pad,
  plus a 25 m/s Gaussian jet (sigma 2 km) at 11 km above sea level;
- heavy-start: 40 kg of ballast aboard above the declared 2400 kg (1.7 %);
- misalignment: the thrust 0.2 deg above the body axis from t = 0;
- ellipsoid-height: the GNSS height is above the ellipsoid, the model's above sea level: +25 m on h;
- doppler-scale: the speed reads 0.3 % high;
- v-latency: only the speed channel 120 ms late (x and h on time): no catalogue family has this
  shape (the channel's own latency, ``sensor_lag_effect``, is opt-in and not in the model file), so
  the case is **out of catalogue** -- only an honest verdict passes;
- four pairs; eight clean seeds.
"""

from __future__ import annotations

import math

from study_harness import Case, one, pair

from .truth import Hidden

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow"})
#: a thrust error's families: burn_rate (thrust and mass flow together on a faster clock) and the thrust
#: profile's located shapes (throttle_step, throttle_window: family thrust_profile, study_harness.LATER_SHAPES)
BLOW = THRUST | {"burn_rate"}
BLOW_NEEDED = frozenset({"thrust_level", "thrust_profile", "burn_rate"})

MIS = math.radians(0.2)
JET = (4.0, 25.0, 11_000.0, 2_000.0)


CASES = (
    Case("blowdown", Hidden(blowdown=0.06), 501,
         "thrust and mass flow falling linearly in propellant used, -6 % at cutoff",
         right=BLOW, needed=BLOW_NEEDED),
    Case("vacuum-nozzle", Hidden(A_e=0.06), 502,
         "sea-level thrust table, nozzle exit 0.06 m^2: P + A_e (p_sl - p(h)), pad at 1400 m",
         right=one("back_pressure"), needed=one("back_pressure"), sizes=(("A_e", 0.06),)),
    Case("cold-day", Hidden(cold_dT=-10.0), 503,
         "column 10 K colder, hydrostatic (density +3.1 % at the pad, -15 % at 30 km), speed of sound standard",
         right=one("density"), needed=one("density")),
    Case("jet-wind", Hidden(jet_wind=JET), 504,
         "tailwind 4 -> 8 m/s (log, first km above the pad) + 25 m/s Gaussian jet at 11 km (sigma 2 km)",
         right=one("wind"), needed=one("wind")),
    Case("heavy-start", Hidden(dm0=40.0), 505,
         "40 kg ballast aboard above the declared 2400 kg",
         right=one("start_mass"), needed=one("start_mass"), sizes=(("dm_start", 40.0),)),
    Case("misalignment", Hidden(delta=MIS), 506,
         "thrust misalignment 0.2 deg from t = 0",
         right=one("misalignment"), needed=one("misalignment"), sizes=(("delta_thrust", MIS),)),
    Case("ellipsoid-height", Hidden(bias_h=25.0), 507,
         "GNSS height above the ellipsoid: h + 25 m",
         right=one("bias_h"), needed=one("bias_h"), sizes=(("b_h", 25.0),)),
    Case("doppler-scale", Hidden(scale_v=0.003), 508,
         "speed reads 0.3 % high",
         right=one("scale_v"), needed=one("scale_v"), sizes=(("k_v", 0.003),)),
    Case("v-latency", Hidden(v_latency=0.12), 509,
         "speed channel alone 120 ms late (x, h on time): out of catalogue",
         out_of_catalogue=True),
    Case("blowdown+jet-wind", Hidden(blowdown=0.06, jet_wind=JET), 510,
         "blowdown -6 % at cutoff + tailwind 4 -> 8 m/s with a 25 m/s jet at 11 km",
         right=BLOW | {"wind"}, needed=BLOW_NEEDED | {"wind"}, needed_each=(BLOW_NEEDED, one("wind"))),
    Case("cold-day+ellipsoid-height", Hidden(cold_dT=-10.0, bias_h=25.0), 511,
         "column 10 K colder + GNSS height 25 m above sea level",
         right=frozenset({"density", "bias_h"}), needed=frozenset({"density", "bias_h"}),
         needed_each=(one("density"), one("bias_h")), sizes=(("b_h", 25.0),)),
    Case("misalignment+heavy-start", Hidden(delta=MIS, dm0=40.0), 512,
         "thrust misalignment 0.2 deg + 40 kg ballast",
         right=frozenset({"misalignment", "start_mass"}), needed=frozenset({"misalignment", "start_mass"}),
         needed_each=(one("misalignment"), one("start_mass")), sizes=(("delta_thrust", MIS), ("dm_start", 40.0))),
    Case("vacuum-nozzle+doppler-scale", Hidden(A_e=0.06, scale_v=0.003), 513,
         "nozzle exit 0.06 m^2 on a sea-level table + speed 0.3 % high",
         right=frozenset({"back_pressure", "scale_v"}), needed=frozenset({"back_pressure", "scale_v"}),
         needed_each=(one("back_pressure"), one("scale_v")), sizes=(("A_e", 0.06), ("k_v", 0.003))),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(520, 528))



#: Eight more pairs, made on 2026-11-28 as a probe of the pair of simple effects (a flexible shape of a third
#: family can stand in for two simple effects: Tern-2's cold day with a heavy payload), seeds 531-538.
FRESH = (
    pair("cold-day+heavy-start", Hidden(cold_dT=-10.0, dm0=40.0), 531,
          "column 10 K colder + 40 kg ballast", one("density"), one("start_mass"), sizes=(("dm_start", 40.0),)),
    pair("vacuum-nozzle+cold-day", Hidden(A_e=0.06, cold_dT=-10.0), 532,
          "nozzle exit 0.06 m^2 on a sea-level table + column 10 K colder", one("back_pressure"), one("density"),
          sizes=(("A_e", 0.06),)),
    pair("blowdown+heavy-start", Hidden(blowdown=0.06, dm0=40.0), 533,
          "blowdown -6 % at cutoff + 40 kg ballast", BLOW_NEEDED, one("start_mass"), sizes=(("dm_start", 40.0),),
          also=BLOW),
    pair("jet-wind+ellipsoid-height", Hidden(jet_wind=JET, bias_h=25.0), 534,
          "tailwind 4 -> 8 m/s with a 25 m/s jet at 11 km + GNSS height 25 m above sea level", one("wind"),
          one("bias_h"), sizes=(("b_h", 25.0),)),
    pair("misalignment+doppler-scale", Hidden(delta=MIS, scale_v=0.003), 535,
          "thrust misalignment 0.2 deg + speed 0.3 % high", one("misalignment"), one("scale_v"),
          sizes=(("delta_thrust", MIS), ("k_v", 0.003))),
    pair("blowdown+cold-day", Hidden(blowdown=0.06, cold_dT=-10.0), 536,
          "blowdown -6 % at cutoff + column 10 K colder", BLOW_NEEDED, one("density"), also=BLOW),
    pair("heavy-start+jet-wind", Hidden(dm0=40.0, jet_wind=JET), 537,
          "40 kg ballast + tailwind 4 -> 8 m/s with a 25 m/s jet at 11 km", one("start_mass"), one("wind"),
          sizes=(("dm_start", 40.0),)),
    pair("vacuum-nozzle+misalignment", Hidden(A_e=0.06, delta=MIS), 538,
          "nozzle exit 0.06 m^2 on a sea-level table + thrust misalignment 0.2 deg", one("back_pressure"),
          one("misalignment"), sizes=(("A_e", 0.06), ("delta_thrust", MIS))),
)

ALL = CASES + FRESH
BY_NAME = {c.name: c for c in ALL}
