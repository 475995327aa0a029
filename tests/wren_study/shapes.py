"""Refit chosen effect sets on one Wren-H case, from the diagnosis's own base fit, and judge each.

What a diagnosis does at its first step, for effect sets of one's choosing -- the catalogue's entries by
name, and three shapes that are not (yet) in it, with their knots over the motor's burn (0.59-15.5 s of
the 44 s flight) instead of over the whole horizon:

* ``burn_rate``: the catalogue's refined thrust shape (a faster clock), by name;
* ``powered_profile<N>``: a thrust error piecewise linear in time on N knots over the burn, flat after it
  (``P (1 + eps(t))``; realistic 0.02 per knot, as ``thrust_profile``);
* ``powered_throttle<N>``: thrust **and** mass flow scaled together on N knots over the burn
  (:func:`rocketid.diagnostics.throttle_effect` with open ends).

Join effects of one set with ``+``. The noise comes from the data's differences (``--sigma estimate``),
the mesh and the noise band are the diagnosis's. Each set is refitted from the base fit, in two worker
processes, and judged by the acceptance test (at the Bonferroni count of the sets given). Run::

    ROCKETID_WREN_DIR=/tmp/er/wren3 python3 tests/wren_study/shapes.py burn-through powered_profile9 thrust_level
    ROCKETID_WREN_DIR=/tmp/er/wren3 python3 tests/wren_study/shapes.py hot-tank burn_rate burn_rate+powered_throttle5

The case's CSV is made (from the truth) in ``$ROCKETID_WREN_DIR`` when it is not there yet.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
for extra in (HERE.parent, HERE.parent / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

from rocketid.diagnostics import CATALOGUE, burn_rate_effect, throttle_effect  # noqa: E402
from rocketid.diagnostics.accept import accept, noise_band  # noqa: E402
from rocketid.diagnostics.api import _read_data, base_fit, resolve_model  # noqa: E402
from rocketid.diagnostics.effects import Effect, _role_definition, piecewise_linear  # noqa: E402
from rocketid.diagnostics.screen import vehicle_of  # noqa: E402
from rocketid.diagnostics.step import _Search  # noqa: E402
from wren_study.cases import BY_NAME  # noqa: E402
from wren_study.run import STUDY  # noqa: E402

#: The motor's burn as the static table states it (s): ignition to zero thrust.
BURN_END = 15.5


def _burn_knots(vehicle, n: int) -> list[float]:
    """``n`` mesh boundaries spread over the burn (from the model's start to :data:`BURN_END`)."""
    b = np.asarray(vehicle.knot_times, float)
    return sorted({float(b[np.argmin(np.abs(b - w))]) for w in np.linspace(b[0], BURN_END, n)})


def _powered_profile(knots: list[float]) -> Effect:
    names = tuple(f"eps_B{j}" for j in range(len(knots)))

    def apply(m):
        sym, thrust = _role_definition(m, "thrust", "powered_profile")
        ps = tuple(m.parameter(name, 0.0, nominal=0.02) for name in names)
        m.redefine(sym, thrust * (1 + piecewise_linear(m.t, knots, ps)))
        return ps
    return Effect(f"powered_profile{len(knots)}", f"thrust error over the burn ({len(knots)} knots)", "propulsion",
                  apply, "thrust P (1 + eps(t)), eps piecewise linear on knots over the burn, flat after it",
                  {name: 0.02 for name in names})


def effect(name: str, vehicle) -> Effect:
    """The effect called ``name`` (module notes)."""
    if name == "burn_rate":
        return burn_rate_effect()
    for stem, make in (("powered_profile", _powered_profile),
                       ("powered_throttle", lambda k: throttle_effect(k, name=f"powered_throttle{len(k)}",
                                                                      open_ends=True))):
        if name.startswith(stem) and name[len(stem):].isdigit():
            return make(_burn_knots(vehicle, int(name[len(stem):])))
    if name not in CATALOGUE:
        raise SystemExit(f"unknown effect {name!r}: give a catalogue name, burn_rate, powered_profile<N> or "
                         "powered_throttle<N>")
    return CATALOGUE[name]


def main(argv: list[str]) -> None:
    if len(argv) < 2 or argv[0] not in BY_NAME:
        raise SystemExit(f"usage: shapes.py CASE SET [SET ...] (CASE one of {', '.join(BY_NAME)}; a SET is "
                         "effect names joined by '+')")
    case, sets = BY_NAME[argv[0]], [s.split("+") for s in argv[1:]]
    spec, _ = resolve_model(str(STUDY.model_file))
    meas, _ = _read_data(str(STUDY.make_data(case)), spec)
    fit, _, counts, _, _ = base_fit(spec, meas, "estimate")
    band = noise_band(fit, estimated=counts)
    print(f"{case.name}: base chi2/dof {fit.chi2_per_dof:.4g}, noise band <= {band.upper:.4g}")
    ctx = _Search(fit.spec, band, vehicle_of(fit), 0.05, None, 600.0, 2, True, None)
    chosen = [[effect(n, ctx.vehicle) for n in s] for s in sets]
    refits = ctx.refit([ctx.task(fit, effects, tuple(e.name for e in effects)) for effects in chosen])
    for s, r in zip(sets, refits):
        judged = accept(r, band, level=0.05, n_tests=len(sets))
        values = ", ".join(f"{n} {v:.4g}" for n, v in zip(r.parameter_names, r.p) if n in r.effect_parameters)
        failed = "; ".join(f"{c.name}: {c.detail}" for c in judged.checks if not c.passed)
        print(f"{'+'.join(s)}: chi2/dof {r.chi2_per_dof:.4g}, BIC {r.bic[1]:.1f}, "
              f"{'accepted' if judged.accepted else 'not accepted'} ({values}){'; ' + failed if failed else ''}")


if __name__ == "__main__":
    main(sys.argv[1:])
