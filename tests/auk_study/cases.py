"""The cases of the booster study: Auk-B with hidden effects at realistic sizes.

Each case names the hidden effects (``truth.Hidden``), the noise seed, and which catalogue
families count as the right answer (``right``: every family in the final model must be one of
these, and one of ``needed`` must be there; for a pair, one of each set in ``needed_each``).
Sizes, relative to Auk-B (60 t at lift-off from a sea-level pad; a liquid core of 600 kN and
210 kg/s at full throttle with a commanded max-q bucket 100 -> 75 % over 28-30 s, held to 43 s,
back to 100 % at 45 s; two strap-on solid boosters of 330-345 kN each at lift-off, regressive to
250 kN at 18 s, progressive to 300 kN at 32 s, burnt out at 38 s, 4 296 kg of grain each; both
1 600 kg casings jettisoned at 40 s, the reference area 5.37 -> 3.80 m^2 there; separation at
8.8 km and Mach 1.32, max q 47 kPa near 34 s; at 110 s 41.7 km, 1.12 km/s, Mach 3.5; GNSS data at
10 Hz, sigma 5 m, 8 m, 0.3 m/s):

- late separation: the boosters leave 1.5 s late, at 41.5 s: their burnt-out casings (3.2 t, 7 % of
  the vehicle then) and their cross-sections are carried 1.5 s longer (up to 2.1 m/s in v and 126 m
  in h);
- cold boosters: a cold grain in both boosters only, each booster's thrust ``0.96 P(t / 1.04)`` and
  its grain burnt at ``mdot(t / 1.04) / 1.04`` -- 4 % low, the burn 4 % longer (tail-off over at
  39.5 s, still before separation); the core unaffected;
- core misalignment: the core engine's thrust axis 0.25 deg above the body axis from lift-off (the
  boosters' thrust along the body); about a third of the thrust during the boost, all of it after;
- jet stream: a headwind of 3 m/s from the ground up with a jet core of 35 m/s at 11 km (its excess
  halved 3 km below the core and 5 km above);
- altitude bias: the GNSS altitude reads 20 m high, constant (2.5 sigma per sample, visible through
  its 1100 samples);
- cold day: the 1976 temperature profile 12 K colder over the whole column, pressure from the
  hydrostatic equation (density +4.3 % at the ground, -1.9 % at 11 km, -17 % at 30 km); the speed of
  sound falls with the temperature (Mach 2.1-2.9 % higher);
- deep bucket: the core engine delivered 70 % where the flight computer commanded 75 %, thrust and
  mass flow together, the commanded ramps scaled (28-45 s);
- latency: every GNSS channel's value at tag t is the flight's at t - 0.15 s (1.5 samples);
- weak booster: one booster's grain lit on only part of its surface: that booster's thrust and grain
  flow 12 % low over its whole burn (6 % of the pair's thrust), the grain left (516 kg) carried to
  separation and dropped with the casing;
- four pairs (late separation + jet stream, cold boosters + altitude bias, core misalignment + cold
  day, deep bucket + latency); four clean seeds.

Seeds 501-509 (one effect), 510-513 (pairs), 520-523 (clean).
"""

from __future__ import annotations

import math

from study_harness import Case, one, pair

from .truth import Hidden

#: Thrust error families: a level, a shape in time (throttle_step / throttle_window map there), the motor's clock.
THRUST = frozenset({"thrust_level", "thrust_profile", "burn_rate"})
#: A booster-phase thrust shortfall. Its own physics is a propulsion error (THRUST, needed). For x, h and v only
#: the acceleration F/m is seen, and a vehicle heavier until separation (start_mass with its refined shape
#: mass_jettison: a mass released at an estimated time) gives, to first order, the same F/m over the boost -- the
#: truth even carries unburnt grain to separation in the weak-booster case -- so a mass family is right beside it;
#: and the mass flow is part of each truth (a slower or weaker grain burns less). Not needed: neither follows the
#: booster's tail-off, which moves (cold) or keeps its shape (weak) under the thrust.
BOOSTER_SHORT = THRUST | {"mass_flow", "start_mass"}
#: The deep bucket (as the telemetry study's): only a shape in time says "the bucket" (thrust_profile: the
#: throttle_window); a level or a mass-flow error is the wrong shape alone, right beside it. burn_rate is not
#: right: it moves a commanded schedule in time, which the engine did not do.
BUCKET = frozenset({"thrust_profile", "thrust_level", "mass_flow"})
#: The late separation is 3.2 t carried for 1.5 s (and the larger area): a mass event in time (start_mass's
#: mass_jettison) or, for x, h and v the same F/m, a thrust dip over those 1.5 s (thrust_profile's
#: throttle_window / throttle_step). The extra drag of the boosters' cross-sections (1.57 m^2 more, about as
#: large a force as the mass's over 40-41.5 s) is real, so a drag family beside them is right, not needed.
LATE_SEP = frozenset({"start_mass", "thrust_profile"})
LATE_SEP_ALSO = frozenset({"transonic_drag", "drag_mach"})

LATE = 1.5
COLD = (0.96, 1.04)
MIS = math.radians(0.25)
JET = (35.0, 11_000.0, 3.0)
BIAS_H = 20.0
COLD_DAY = -12.0
BUCKET_LEVEL = 0.70
LATENCY = 0.15
WEAK = 0.12


CASES = (
    Case("late-separation", Hidden(sep_delay=LATE), 501,
         "boosters separate 1.5 s late (41.5 s): 3.2 t of casings and their area carried longer",
         right=LATE_SEP | LATE_SEP_ALSO, needed=LATE_SEP),
    Case("cold-boosters", Hidden(cold_boosters=COLD), 502,
         "both boosters 4 % low and 4 % slower, 0.96 P(t/1.04), grain flow with it; core unaffected",
         right=BOOSTER_SHORT, needed=THRUST),
    # the catalogue's misalignment turns the whole thrust; the truth's only the core's (about a third of it in
    # the boost, all of it after): delta_thrust 0.25 deg is the after-boost value
    Case("core-misalignment", Hidden(core_misalign=MIS), 503,
         "core engine thrust 0.25 deg above the body axis from lift-off (boosters aligned)",
         right=one("misalignment"), needed=one("misalignment"), sizes=(("delta_thrust", MIS),)),
    Case("jet-stream", Hidden(jet=JET), 504,
         "headwind 3 m/s from the ground, jet core 35 m/s at 11 km (half 3 km below, 5 km above)",
         right=one("wind"), needed=one("wind")),
    Case("h-bias", Hidden(bias_h=BIAS_H), 505,
         "GNSS altitude 20 m high (constant)",
         right=one("bias_h"), needed=one("bias_h"), sizes=(("b_h", BIAS_H),)),
    Case("cold-day", Hidden(dT=COLD_DAY), 506,
         "day 12 K colder over the column, hydrostatic (density +4 % at 0, -17 % at 30 km; Mach +2-3 %)",
         right=one("density"), needed=one("density"), sizes=(("dT_air", COLD_DAY),)),
    Case("deep-bucket", Hidden(bucket_level=BUCKET_LEVEL), 507,
         "core bucket delivered at 70 % where 75 % was commanded (thrust and mass flow), 28-45 s",
         right=BUCKET, needed=one("thrust_profile")),
    Case("latency", Hidden(latency=LATENCY), 508,
         "GNSS time tags 0.15 s late on every channel (exact shift)",
         right=one("time_offset"), needed=one("time_offset"), sizes=(("tau", LATENCY),)),
    Case("weak-booster", Hidden(weak_booster=WEAK), 509,
         "one booster 12 % weak over its burn (6 % of the pair's thrust, grain flow with it; 516 kg left "
         "dropped at separation)",
         right=BOOSTER_SHORT, needed=THRUST),
    pair("late-separation+jet-stream", Hidden(sep_delay=LATE, jet=JET), 510,
         "boosters separate 1.5 s late + headwind jet 35 m/s at 11 km", LATE_SEP, one("wind"), also=LATE_SEP_ALSO),
    pair("cold-boosters+h-bias", Hidden(cold_boosters=COLD, bias_h=BIAS_H), 511,
         "boosters 4 % low and 4 % slower + GNSS altitude 20 m high", THRUST, one("bias_h"),
         also=BOOSTER_SHORT, sizes=(("b_h", BIAS_H),)),
    pair("core-misalignment+cold-day", Hidden(core_misalign=MIS, dT=COLD_DAY), 512,
         "core thrust 0.25 deg off the body axis + day 12 K colder", one("misalignment"), one("density"),
         sizes=(("delta_thrust", MIS), ("dT_air", COLD_DAY))),
    pair("deep-bucket+latency", Hidden(bucket_level=BUCKET_LEVEL, latency=LATENCY), 513,
         "core bucket at 70 % for 75 % commanded + GNSS time tags 0.15 s late", one("thrust_profile"),
         one("time_offset"), also=BUCKET, sizes=(("tau", LATENCY),)),
) + tuple(Case(f"clean-{seed}", Hidden(), seed, f"clean (seed {seed})") for seed in range(520, 524))

ALL = CASES
BY_NAME = {c.name: c for c in ALL}
