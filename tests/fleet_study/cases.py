"""The campaigns of the fleet study: three flights of Petrel-V each, noise unknown to the diagnosis.

A **campaign** is three flights (A, B, C) of the same vehicle. Each flight has its own day (:class:`Day`):

- its own noise seed and its own noise **level**: Petrel's GNSS (x 3 m, h 4 m, v 0.15 m/s) times the flight's
  factor -- A x1, B x1.5, C x0.7 -- so that "unknown noise" is real (the diagnosis must take each flight's
  noise from its own data: ``--sigma estimate``); the CSVs state no sigma at all (``write_csv``);
- optionally effects of its own (``own``): a GNSS height offset, a jet-stream wind -- properties of that
  flight's day or receiver, never of the vehicle.

The campaign may hide **one property of the vehicle in every flight** (``shared``): the nozzle's exit area on a
sea-level thrust table, a thrust misalignment, the blowdown of the tank pressure, a payload adapter of 40 kg
that nobody declared. The truth is ``tests/petrel_study/truth.py`` (Earth-centred Cartesian states, its own
1976 atmosphere, every hidden effect in its own shape, written apart from the effect catalogue), used as is.

Which catalogue families count as right was decided from the physics and the user documentation
(docs/several-flights.md, the table of effect natures) before any diagnosis ran:

- nozzle (``A_e`` 0.06 m^2): ``back_pressure`` (with its refined shapes, family ``back_pressure``), a vehicle
  effect: expected in every flight (found or carried) and **one** ``A_e`` in the joint model, close to 0.06;
- misalignment 0.2 deg: ``misalignment``, a vehicle effect: one ``delta_thrust`` close to 0.00349 rad;
- blowdown (thrust and mass flow -6 % at cutoff, linear in propellant used): the thrust families
  (``thrust_level``, ``thrust_profile``, ``mass_flow``, ``burn_rate``; needed: one of ``thrust_level``,
  ``thrust_profile``, ``burn_rate``), as in the Petrel study; vehicle effects, expected shared in the joint
  model. No catalogue parameter *is* the truth's blowdown, so no value is scored (only that it is shared);
- 40 kg payload adapter in every flight: ``start_mass`` (its refined shapes included). In rocketid's rules the
  start mass is **the flight's own loading** (docs/several-flights.md: "the loading (``start_mass``,
  ``start_mass_exit``) ... always one value per flight"). The adapter is physically the same on every flight,
  but nothing in three flights' data can tell a fixed adapter from three loadings that happen to agree, and the
  documentation says a user would get one value per flight. So the right answer here is ``start_mass`` in each
  flight, kept **per flight** (``dm_start[A]``, ``[B]``, ``[C]``), each value close to 40 kg; a joint model
  that shared it would contradict the documented rule and is scored as a problem;
- a flight's own height offset: ``bias_h`` in that flight only (``b_h[flight]`` close to the truth);
- a flight's own jet wind: ``wind`` in that flight only (no value scored: the truth's profile is no catalogue
  shape);
- a clean flight adds nothing, and nothing is carried into it.

"Close" is within 10 % of the truth or 3 standard errors, whichever is larger.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

_TESTS = Path(__file__).resolve().parent.parent
for _extra in (_TESTS, _TESTS / "vehicles"):
    if str(_extra) not in sys.path:
        sys.path.insert(0, str(_extra))

import petrel as V  # noqa: E402
from petrel_study import truth  # noqa: E402
from petrel_study.truth import Hidden  # noqa: E402
from study_harness import one  # noqa: E402

#: The channels a CSV holds, in column order (the model's outputs).
CHANNELS = ("x", "h", "v")
#: Each flight's noise: Petrel's GNSS sigmas times this factor.
NOISE = {"A": 1.0, "B": 1.5, "C": 0.7}

THRUST = frozenset({"thrust_level", "thrust_profile", "mass_flow", "burn_rate"})
THRUST_NEEDED = frozenset({"thrust_level", "thrust_profile", "burn_rate"})
MIS = math.radians(0.2)
#: Flight C's jet in campaign "own-days" (the Petrel study's): 4 -> 8 m/s in the first km, 25 m/s at 11 km.
JET = (4.0, 25.0, 11_000.0, 2_000.0)
#: Flight C's jet in campaign "nozzle+C-wind": another day, 3 -> 6 m/s, 20 m/s at 12 km, sigma 2.5 km.
JET_2 = (3.0, 20.0, 12_000.0, 2_500.0)


@dataclass(frozen=True)
class Day:
    """One flight of a campaign: its label (the CSV's name), noise seed and level, and its own effects."""

    label: str
    seed: int
    noise: float                        # factor on Petrel's GNSS sigmas
    own: tuple = ()                     # (Hidden field, value): effects of this flight only
    words: str = "clean"
    right: frozenset = frozenset()      # families right for the flight's own effects
    needed_each: tuple = ()             # one family of each set must be in this flight's final model
    sizes: tuple = ()                   # (parameter, true value) of the flight's own effects

    @property
    def sigma(self) -> dict:
        """The noise standard deviations this flight's data were made with (never written to the CSV)."""
        return {ch: V.SIGMA[ch] * self.noise for ch in CHANNELS}


@dataclass(frozen=True)
class Campaign:
    """Three flights of Petrel-V and, optionally, one property of the vehicle hidden in all of them."""

    name: str
    truth: str                          # in words, for the table
    days: tuple
    shared: tuple = ()                  # (Hidden field, value) in every flight
    shared_right: frozenset = frozenset()
    shared_needed: frozenset = frozenset()
    shared_nature: str | None = None    # "vehicle": one value in the joint model; "flight": one per flight
    shared_sizes: tuple = ()            # (parameter, true value) of the shared property
    shared_change: tuple = ()           # (channel, low, high): the shared property's largest change in every flight

    def hidden(self, day: Day) -> Hidden:
        """The truth's hidden effects of one flight: the campaign's shared ones and the flight's own."""
        return Hidden(**dict(self.shared), **dict(day.own))

    def right(self, day: Day) -> frozenset:
        return self.shared_right | day.right

    def needed_each(self, day: Day) -> tuple:
        return ((self.shared_needed,) if self.shared_needed else ()) + tuple(day.needed_each)

    @property
    def clean(self) -> bool:
        return not self.shared and not any(d.own for d in self.days)

    def day(self, label: str) -> Day:
        return {d.label: d for d in self.days}[label]


def _days(seeds, own=None) -> tuple:
    """Days A, B, C with the study's noise factors; ``own`` maps a label to (own, words, right, needed_each, sizes)."""
    own = own or {}
    out = []
    for label, seed in zip("ABC", seeds):
        if label in own:
            hid, words, right, needed_each, sizes = own[label]
            out.append(Day(label, seed, NOISE[label], hid, words, right, needed_each, sizes))
        else:
            out.append(Day(label, seed, NOISE[label]))
    return tuple(out)


NOZZLE = dict(shared=(("A_e", 0.06),), shared_right=one("back_pressure"), shared_needed=one("back_pressure"),
              shared_nature="vehicle", shared_sizes=(("A_e", 0.06),))

CAMPAIGNS = (
    Campaign("clean", "three clean flights", _days((641, 642, 643))),
    Campaign("nozzle", "nozzle exit 0.06 m^2 on a sea-level thrust table, every flight", _days((644, 645, 646)),
             shared_change=(("v", 80.0, 150.0),), **NOZZLE),
    Campaign("misalignment", "thrust 0.2 deg off the body axis, every flight", _days((647, 648, 649)),
             shared=(("delta", MIS),), shared_right=one("misalignment"), shared_needed=one("misalignment"),
             shared_nature="vehicle", shared_sizes=(("delta_thrust", MIS),), shared_change=(("x", 25.0, 60.0),)),
    Campaign("adapter-mass", "40 kg payload adapter nobody declared, every flight", _days((650, 651, 652)),
             shared=(("dm0", 40.0),), shared_right=one("start_mass"), shared_needed=one("start_mass"),
             shared_nature="flight", shared_sizes=(("dm_start", 40.0),), shared_change=(("v", 20.0, 45.0),)),
    Campaign("own-days", "no vehicle effect; B's GNSS height 25 m high, C flew through a jet stream",
             _days((653, 654, 655), {
                 "B": ((("bias_h", 25.0),), "h + 25 m", one("bias_h"), (one("bias_h"),), (("b_h", 25.0),)),
                 "C": ((("jet_wind", JET),), "jet 4 -> 8 m/s + 25 m/s at 11 km", one("wind"), (one("wind"),), ()),
             })),
    Campaign("nozzle+C-wind", "nozzle exit 0.06 m^2 every flight; C flew through a jet stream",
             _days((656, 657, 658), {
                 "C": ((("jet_wind", JET_2),), "jet 3 -> 6 m/s + 20 m/s at 12 km", one("wind"), (one("wind"),), ()),
             }), shared_change=(("v", 80.0, 150.0),), **NOZZLE),
    Campaign("blowdown+A-height", "blowdown -6 % at cutoff every flight; A's GNSS height 20 m high",
             _days((659, 660, 661), {
                 "A": ((("bias_h", 20.0),), "h + 20 m", one("bias_h"), (one("bias_h"),), (("b_h", 20.0),)),
             }), shared=(("blowdown", 0.06),), shared_right=THRUST, shared_needed=THRUST_NEEDED,
             shared_nature="vehicle", shared_change=(("v", 40.0, 100.0),)),
    Campaign("clean-2", "three clean flights, other seeds", _days((662, 663, 664))),
)

BY_NAME = {c.name: c for c in CAMPAIGNS}


@lru_cache(maxsize=None)
def exact(hidden: Hidden) -> dict:
    """The truth's noise-free x, h, v at Petrel's GNSS sample times (read-only arrays)."""
    out = truth.exact_outputs(hidden, V.sample_times())
    for a in out.values():
        a.flags.writeable = False
    return out


def noisy(campaign: Campaign, day: Day) -> dict:
    """One flight's measurements: the truth plus N(0, (factor * Petrel's sigma)^2), seeded by the day."""
    rng = np.random.default_rng(day.seed)
    clean = exact(campaign.hidden(day))
    times = V.sample_times()
    return {ch: clean[ch] + day.sigma[ch] * rng.standard_normal(times.size) for ch in CHANNELS}


def write_csv(path: Path, times, values: dict) -> Path:
    """A telemetry file as a user has one: ``t,x,h,v`` and nothing about the noise (no sigma column, no header
    comment). Written to a temporary name and renamed, so a half-written file is never read."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(",".join(("t",) + CHANNELS) + "\n")
        for i, t in enumerate(times):
            fh.write(",".join([repr(float(t))] + [repr(float(values[ch][i])) for ch in CHANNELS]) + "\n")
    os.replace(tmp, path)
    return path


def write_campaign(campaign: Campaign, folder: Path) -> list[Path]:
    """The campaign's three CSVs, ``folder/A.csv``, ``B.csv``, ``C.csv`` (deterministic: the truth is, the noise
    is seeded; rewritten each time)."""
    times = V.sample_times()
    return [write_csv(Path(folder) / f"{day.label}.csv", times, noisy(campaign, day)) for day in campaign.days]
