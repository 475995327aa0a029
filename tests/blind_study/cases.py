"""The blind study's cases: hidden effects on Halcyon-8, with the right catalogue families.

Each case gives the truth's ``effects`` (see :func:`truth.simulate`), the noise seed and
``right``: the catalogue effect NAMES (docs/effects.md tables) accepted as the right family for
that physics, decided BEFORE any diagnosis ran. A pair lists one family set per component
(``right`` is a list of sets); ``right = None`` for a clean case (the right answer is "nothing
missing"). Refined-shape names with a knot count match by prefix (``thrust_profile_``,
``wind_pl_``, ``density_pl_``, ``drag_mach_``, ``bias_h_drift`` ...).

Decisions (written before running):

- throttle_bucket: thrust AND mass flow 20 % down 30-45 s, 3 s ramps. Family: the thrust
  error (thrust_level, thrust_profile_N); mass_flow is part of the physics too.
- induced_drag: CD + k alpha^2, k = 3 (= CN_alpha, the axial/normal split of a slender body).
  No catalogue term is in alpha; a drag-coefficient correction (transonic_drag, drag_mach_N)
  is accepted as the right family (the drag coefficient is what is wrong).
- altimeter_scale: h measured 0.4 % high (140 m at burn-out). No exact term; the h-sensor
  family (bias_h, bias_h_drift) is accepted.
- v_lag: speed sensor a first-order lag, tau 80 ms. The v-sensor family (bias_v,
  bias_v_drift, scale_v) is accepted; time_offset (a delay of EVERY channel) is not.
- dropped_mass: 150 kg released at 55 s. The mass family (start_mass, mass_flow).
- wind_shear: horizontal wind +10 m/s near the ground (tanh over 300 m) reversing to a
  -25 m/s (uprange) jet at 10.5 km. Family wind, wind_pl_N.
- cold_day: hydrostatic atmosphere 10 K colder at every altitude (p(0) standard; density and
  speed of sound both change). Family density, density_pl_N.
- misalign_late: thrust 0.2 deg off the body axis (towards up) from t = 20 s on. Family
  misalignment, misalignment_fade.
- isp_shortfall: thrust 2.5 % low, mass flow nominal. Family thrust_level, thrust_profile_N.
- bias_h8: altitude sensor +8 m. Family bias_h, bias_h_drift.
- pairs: isp_shortfall + bias_h8; wind_shear + v_lag.
- four clean seeds.
"""

from __future__ import annotations

# throttle_step and throttle_window, the thrust family's event shapes, were added after the study was written
# (2026-11-25 and 2026-11-26)
THRUST = {"thrust_level", "thrust_profile_", "throttle_step", "throttle_window"}
# mass_jettison, the start-mass family's event shape, was added after the study was written (2026-11-25)
MASS = {"mass_flow", "start_mass", "mass_jettison"}
# drag_bump, the drag family's hump at an estimated Mach number, was added after the study was written (2026-11-26)
DRAG = {"transonic_drag", "drag_mach_", "drag_bump"}
# scale_h, the altimeter's scale factor, was added to the catalogue after the study was written (2026-11-25)
HSENS = {"bias_h", "bias_h_drift", "scale_h"}
VSENS = {"bias_v", "bias_v_drift", "scale_v"}
WIND = {"wind", "wind_pl_"}
# burn_rate, the thrust family's shape that scales thrust and mass flow together on a faster motor clock, was
# added after the study was written (2026-11-26, for the air-launch study's hot motor); it is right where the
# truth changes both (the throttle bucket), not for a thrust error at the stated mass flow (isp_shortfall)
BURN = {"burn_rate"}
# temperature, the atmosphere's temperature offset (density and speed of sound), was added to the catalogue
# after the study was written (2026-11-26, because an air-launch study's cold day was explained by a wind)
DENS = {"density", "density_pl_", "temperature"}
# misalignment_onset, the family's shape with an onset time, was added to the catalogue after this study was
# written (2026-11-25, because the late misalignment was explained by a wind); it is the same family
MISAL = {"misalignment", "misalignment_fade", "misalignment_onset"}

THROTTLE = {"depth": 0.20, "t_on": 30.0, "t_off": 45.0, "ramp": 3.0}
WIND_SHEAR = {"surface": 10.0, "jet": 25.0, "jet_alt": 10_500.0, "jet_width": 2_500.0}

CASES = {
    # name: (truth text, effects, seed, right)
    "clean-s11": ("no hidden effect (seed 11)", {}, 11, None),
    "bias_h8": ("altitude sensor +8 m", {"b_h": 8.0}, 101, [HSENS]),
    "isp_shortfall": ("thrust 2.5 % low, mass flow nominal", {"thrust_eps": -0.025}, 102, [THRUST]),
    "altimeter_scale": ("h measured 0.4 % high", {"h_scale": 0.004}, 103, [HSENS]),
    "v_lag": ("speed sensor first-order lag tau 80 ms", {"v_lag": 0.080}, 104, [VSENS]),
    "dropped_mass": ("150 kg released at 55 s", {"drop": {"t": 55.0, "dm": 150.0}}, 105, [MASS]),
    "throttle_bucket": ("thrust and mass flow -20 % 30-45 s (3 s ramps)", {"throttle": THROTTLE}, 106,
                        [THRUST | MASS | BURN]),
    "misalign_late": ("thrust misalignment 0.2 deg from t = 20 s", {"misalign": {"delta": 0.2 * 3.141592653589793 / 180,
                                                                                 "t_on": 20.0}}, 107, [MISAL]),
    "cold_day": ("hydrostatic atmosphere 10 K colder (rho and a)", {"dT": -10.0}, 108, [DENS]),
    "wind_shear": ("wind +10 m/s near ground reversing to -25 m/s jet at 10.5 km", {"wind_shear": WIND_SHEAR}, 109,
                   [WIND]),
    "induced_drag": ("CD + 3 alpha^2", {"induced_k": 3.0}, 110, [DRAG]),
    "pair-isp+bias_h": ("thrust 2.5 % low + altitude sensor +8 m", {"thrust_eps": -0.025, "b_h": 8.0}, 111,
                        [THRUST, HSENS]),
    "pair-wind+v_lag": ("wind shear (as wind_shear) + speed lag 80 ms", {"wind_shear": WIND_SHEAR, "v_lag": 0.080},
                        112, [WIND, VSENS]),
    "clean-s12": ("no hidden effect (seed 12)", {}, 12, None),
    "clean-s13": ("no hidden effect (seed 13)", {}, 13, None),
    "clean-s14": ("no hidden effect (seed 14)", {}, 14, None),
    # follow-ups, added AFTER the main run because misalign_late came out "explained" by wind:
    # the same physics on other seeds / sign, and the catalogue-exact shape (from t = 0) as a control.
    "x-misalign_late-s2": ("thrust misalignment 0.2 deg from t = 20 s (seed 207)",
                           {"misalign": {"delta": 0.2 * 3.141592653589793 / 180, "t_on": 20.0}}, 207, [MISAL]),
    "x-misalign_late-neg": ("thrust misalignment -0.2 deg from t = 20 s",
                            {"misalign": {"delta": -0.2 * 3.141592653589793 / 180, "t_on": 20.0}}, 208, [MISAL]),
    "x-misalign_t0": ("thrust misalignment 0.2 deg from t = 0 (catalogue shape)",
                      {"misalign": {"delta": 0.2 * 3.141592653589793 / 180, "t_on": 0.0}}, 209, [MISAL]),
}


def matches(name: str, family: set) -> bool:
    """Whether catalogue effect ``name`` belongs to ``family`` (prefix entries end with '_')."""
    return any(name == f or (f.endswith("_") and name.startswith(f)) for f in family)
