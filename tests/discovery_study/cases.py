"""The study's cases, as data.

Each case names a vehicle (``ra66``: the chapter's time-knot model; ``ra66m``: CD(Mach),
CL_alpha alpha; ``stage30``: the user's 30 t stage in ``tests/vehicles/stage30.py``), the hidden
effects of its truth (``truth.truth_model`` / ``truth.measure``) with their sizes, and the noise
seed. Sizes are realistic for the vehicle (docs/effects.md): back-pressure ``A_e p0`` 10 % of the
sea-level thrust, thrust error 2 %, mass-flow error 1.5 %, misalignment 0.25 deg, a 40-45 m/s
jet core between the catalogue's basis altitudes, density deviations of 3-6 %, Earth rotation at
28.5 deg N launching east, a transonic rise of 0.12-0.15 in CD, biases of 5 m and 0.5 m/s,
a 0.1 % speed scale factor, a one-sample (10 ms) time-tag offset.

``expect`` maps the catalogue parameter names to the truth's value where the catalogue's
parameter means the same number (scalar effects); profile effects (wind, density, a drifting
thrust error, the transonic rise) have another shape than the catalogue's, so their sizes are
reported against the truth's profile (``profile``), not asserted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .truth import CATALOGUE_NAME, density_deviation, wind_profile


@dataclass(frozen=True)
class Case:
    """One study case.

    Attributes
    ----------
    id : str
    vehicle : {"ra66", "ra66m", "stage30"}
    effects : dict
        ``{truth effect: {size: value}}`` (empty: clean data).
    seed : int
    fast : bool
        In the normal (not slow) test suite.
    """

    id: str
    vehicle: str
    effects: dict = field(default_factory=dict)
    seed: int = 0
    fast: bool = False

    @property
    def true_names(self) -> tuple[str, ...]:
        """The catalogue effects that stand for the truth's effects."""
        return tuple(sorted({CATALOGUE_NAME[k] for k in self.effects}))

    @property
    def clean(self) -> bool:
        return not self.effects

    @property
    def expect(self) -> dict[str, float]:
        """Catalogue parameter -> true value, for the scalar effects."""
        out = {}
        e = self.effects
        if "back_pressure" in e:
            out["A_e"] = e["back_pressure"]["A_e"]
        if "thrust_level" in e:
            out["eps_thrust"] = e["thrust_level"]["eps_thrust"]
        if "mass_flow" in e:
            out["eps_mdot"] = e["mass_flow"]["eps_mdot"]
        if "misalignment" in e:
            out["delta_thrust"] = math.radians(e["misalignment"]["delta_deg"])
        if "earth_rotation" in e and e["earth_rotation"] == ROTATION:
            out["k_rot"] = 1.0          # the catalogue's site; another site's is judged by its name
        for name, par in (("bias_x", "b_x"), ("bias_h", "b_h"), ("bias_v", "b_v"), ("scale_v", "k_v"),
                          ("time_offset", "tau")):
            if name in e:
                out[par] = e[name][par]
        return out

    @property
    def profile(self) -> str:
        """The truth of the profile effects, in words and numbers."""
        parts = []
        e = self.effects
        if "wind" in e:
            w = e["wind"]
            at = ", ".join(f"{z:g} km {float(wind_profile(z * 1000.0, **w)):.1f}" for z in (0, 3, 8, 10.5, 13, 18))
            parts.append(f"wind: surface {w['surface']:g} m/s{' (grown over ' + str(w['layer_m']) + ' m)' if w.get('layer_m') else ''}, "
                         f"sech^2 jet {w['jet']:g} m/s at {w['core_km']:g} km (half-width {w['width_km']:g} km); "
                         f"W(h) m/s: {at}")
        if "density" in e:
            a = e["density"]["amplitude"]
            at = ", ".join(f"{z:g} km {100 * float(density_deviation(z * 1000.0, amplitude=a)):+.1f} %"
                           for z in (0, 6, 12, 18))
            parts.append(f"density: {a:g} tanh((h - 8 km)/12 km): {at}")
        if "thrust_drift" in e:
            d = e["thrust_drift"]
            parts.append(f"thrust error drifting {100 * d['eps_start']:+.1f} % -> {100 * d['eps_end']:+.1f} % over 66 s")
        if "transonic_drag" in e:
            parts.append(f"transonic rise +{e['transonic_drag']['peak']:g} CD at M 1.02 (asymmetric)")
        return "; ".join(parts)

    def truth_text(self) -> str:
        if self.clean:
            return f"clean (seed {self.seed})"
        bits = []
        for k, v in self.effects.items():
            if k == "back_pressure":
                bits.append(f"back-pressure A_e {v['A_e']:g} m^2 from sea-level thrust")
            elif k == "thrust_level":
                bits.append(f"thrust {100 * v['eps_thrust']:+g} %")
            elif k == "thrust_drift":
                bits.append(f"thrust {100 * v['eps_start']:+g} -> {100 * v['eps_end']:+g} %")
            elif k == "mass_flow":
                bits.append(f"mass flow {100 * v['eps_mdot']:+g} %")
            elif k == "misalignment":
                bits.append(f"misalignment {v['delta_deg']:g} deg from t = 0")
            elif k == "wind":
                bits.append(f"wind {v['surface']:g} m/s surface + {v['jet']:g} m/s jet at {v['core_km']:g} km")
            elif k == "density":
                bits.append(f"density {v['amplitude']:g} tanh profile")
            elif k == "earth_rotation":
                bits.append(f"Earth rotation {v['latitude_deg']:g} N az {v['azimuth_deg']:g}")
            elif k == "transonic_drag":
                bits.append(f"transonic rise {v['peak']:g}")
            elif k == "bias_x":
                bits.append(f"x bias {v['b_x']:g} m")
            elif k == "bias_h":
                bits.append(f"h bias {v['b_h']:g} m")
            elif k == "bias_v":
                bits.append(f"v bias {v['b_v']:g} m/s")
            elif k == "scale_v":
                bits.append(f"v scale {100 * v['k_v']:g} %")
            elif k == "time_offset":
                bits.append(f"time offset {1000 * v['tau']:g} ms")
        return " + ".join(bits)


BP30 = {"A_e": 0.6}                # A_e p0 = 60.8 kN, 10 % of 610 kN at sea level
BP66 = {"A_e": 0.4}                # 40.5 kN, 10 % of 400 kN
WIND30 = {"surface": 5.0, "jet": 45.0, "core_km": 10.5, "width_km": 2.0}
WIND66 = {"surface": 5.0, "jet": 40.0, "core_km": 11.2, "width_km": 2.5, "layer_m": 300.0}
DENSITY = {"amplitude": 0.06}
ROTATION = {"latitude_deg": 28.5, "azimuth_deg": 90.0}

SINGLE = [
    # the user's vehicle: every catalogue effect
    Case("s30-back_pressure", "stage30", {"back_pressure": BP30}, seed=11),
    Case("s30-thrust_level", "stage30", {"thrust_level": {"eps_thrust": 0.02}}, seed=12),
    Case("s30-thrust_drift", "stage30", {"thrust_drift": {"eps_start": 0.03, "eps_end": 0.01}}, seed=13),
    Case("s30-mass_flow", "stage30", {"mass_flow": {"eps_mdot": 0.015}}, seed=14),
    Case("s30-misalignment", "stage30", {"misalignment": {"delta_deg": 0.25}}, seed=15),
    Case("s30-wind", "stage30", {"wind": WIND30}, seed=16),
    Case("s30-density", "stage30", {"density": DENSITY}, seed=17),
    Case("s30-earth_rotation", "stage30", {"earth_rotation": ROTATION}, seed=18),
    Case("s30-transonic_drag", "stage30", {"transonic_drag": {"peak": 0.15}}, seed=19),
    Case("s30-bias_x", "stage30", {"bias_x": {"b_x": 5.0}}, seed=20),
    Case("s30-bias_h", "stage30", {"bias_h": {"b_h": 5.0}}, seed=21, fast=True),
    Case("s30-bias_v", "stage30", {"bias_v": {"b_v": 0.5}}, seed=22),
    Case("s30-scale_v", "stage30", {"scale_v": {"k_v": 1e-3}}, seed=23),
    Case("s30-time_offset", "stage30", {"time_offset": {"tau": 0.01}}, seed=24),
    # RA-66M (CD(Mach), CL_alpha alpha), launched from rest
    Case("m-back_pressure", "ra66m", {"back_pressure": BP66}, seed=31),
    Case("m-wind", "ra66m", {"wind": WIND66}, seed=32),
    Case("m-density", "ra66m", {"density": DENSITY}, seed=33),
    Case("m-transonic_drag", "ra66m", {"transonic_drag": {"peak": 0.12}}, seed=34),
    Case("m-mass_flow", "ra66m", {"mass_flow": {"eps_mdot": 0.015}}, seed=35),
    # RA-66 (the chapter's time-knot CD(t), constant CL)
    Case("r-thrust_level", "ra66", {"thrust_level": {"eps_thrust": 0.02}}, seed=41),
    Case("r-back_pressure", "ra66", {"back_pressure": BP66}, seed=42),
    Case("r-bias_h", "ra66", {"bias_h": {"b_h": 5.0}}, seed=43),
]

PAIRS = [
    Case("s30-back_pressure+wind", "stage30", {"back_pressure": BP30, "wind": WIND30}, seed=51),
    Case("s30-misalignment+bias_h", "stage30", {"misalignment": {"delta_deg": 0.25}, "bias_h": {"b_h": 5.0}},
         seed=52),
    Case("s30-earth_rotation+scale_v", "stage30", {"earth_rotation": ROTATION, "scale_v": {"k_v": 1e-3}}, seed=53),
    Case("m-thrust_level+density", "ra66m", {"thrust_level": {"eps_thrust": 0.02}, "density": DENSITY}, seed=54),
    Case("r-thrust_level+bias_h", "ra66", {"thrust_level": {"eps_thrust": 0.02}, "bias_h": {"b_h": 5.0}}, seed=55),
]

#: 20 noise seeds of clean data on the user's vehicle (at most one may add an effect)
CLEAN_SEEDS = tuple(range(100, 120))
CLEAN = [Case(f"s30-clean-{s}", "stage30", {}, seed=s, fast=(s == 100)) for s in CLEAN_SEEDS]
#: clean data on the reference cases too
CLEAN_REF = [Case("m-clean", "ra66m", {}, seed=60), Case("r-clean", "ra66", {}, seed=61)]

#: Variations, not tuned on: other signs and sizes than the cases above, a headwind, another launch site,
#: three effects at once (``benchmarks/discovery_study.py --group varied``; not in the main table).
VARIED = [
    Case("v-s30-thrust_level-neg", "stage30", {"thrust_level": {"eps_thrust": -0.03}}, seed=201),
    Case("v-s30-back_pressure-small", "stage30", {"back_pressure": {"A_e": 0.3}}, seed=202),
    Case("v-s30-misalignment-neg", "stage30", {"misalignment": {"delta_deg": -0.4}}, seed=203),
    Case("v-s30-wind-head", "stage30", {"wind": {"surface": -6.0, "jet": -35.0, "core_km": 9.0, "width_km": 1.5}},
         seed=204),
    Case("v-s30-density-neg", "stage30", {"density": {"amplitude": -0.08}}, seed=205),
    Case("v-s30-mass_flow-neg", "stage30", {"mass_flow": {"eps_mdot": -0.025}}, seed=206),
    Case("v-s30-time_offset-neg", "stage30", {"time_offset": {"tau": -0.02}}, seed=207),
    Case("v-s30-bias_h-neg", "stage30", {"bias_h": {"b_h": -8.0}}, seed=208),
    Case("v-s30-scale_v-neg", "stage30", {"scale_v": {"k_v": -2e-3}}, seed=209),
    Case("v-s30-thrust_drift-neg", "stage30", {"thrust_drift": {"eps_start": -0.01, "eps_end": -0.04}}, seed=210),
    Case("v-s30-earth_rotation-north", "stage30", {"earth_rotation": {"latitude_deg": 45.0, "azimuth_deg": 0.0}},
         seed=211),
    Case("v-m-thrust_level", "ra66m", {"thrust_level": {"eps_thrust": 0.03}}, seed=212),
    Case("v-m-back_pressure-big", "ra66m", {"back_pressure": {"A_e": 0.6}}, seed=213),
    Case("v-r-wind-head", "ra66", {"wind": {"surface": -4.0, "jet": -30.0, "core_km": 12.0, "width_km": 2.0,
                                            "layer_m": 300.0}}, seed=214),
    Case("v-r-mass_flow", "ra66", {"mass_flow": {"eps_mdot": 0.02}}, seed=215),
    Case("v-s30-thrust_level+wind+bias_h", "stage30",
         {"thrust_level": {"eps_thrust": 0.015}, "wind": WIND30, "bias_h": {"b_h": 5.0}}, seed=216),
    Case("v-s30-back_pressure+time_offset+bias_v", "stage30",
         {"back_pressure": BP30, "time_offset": {"tau": 0.01}, "bias_v": {"b_v": 0.5}}, seed=217),
    Case("v-m-transonic_drag+bias_x", "ra66m", {"transonic_drag": {"peak": 0.10}, "bias_x": {"b_x": -5.0}}, seed=218),
]

ALL = SINGLE + PAIRS + CLEAN_REF + CLEAN
BY_ID = {c.id: c for c in ALL + VARIED}
