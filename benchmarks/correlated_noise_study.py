"""The diagnosis on data whose errors are correlated in time (``rocketid.diagnostics.correlated``), with the
channels thinned (the default) and with every sample kept (``correlated_noise="keep"``, the behaviour before).

::

    python benchmarks/correlated_noise_study.py [CASE ...] [--keep]

Each case: a truth flown by a simulator, its sensors' errors white noise through a first-order filter
(``scipy.signal.lfilter``, correlation ``rho`` from one sample to the next, marginal standard deviation the
sensor's sigma), the sigma stated or estimated from the data. RA-66M uses rocketid's own truth (100 Hz);
Halcyon-8 the blind study's simulator (``tests/blind_study/truth.py``, 10 Hz); its ``second-order`` cases put the
errors through two such filters (a navigation filter's position). One line per case and mode:
final effects, verdict, chi2/dof, the effect's estimate, the noise from the data, the time.
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

ROOT = Path(__file__).resolve().parents[1]
for extra in (ROOT / "tests", ROOT / "tests" / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import rocketid as ri  # noqa: E402
from rocketid.diagnostics import diagnose, with_effects  # noqa: E402

HALCYON = str(ROOT / "tests" / "vehicles" / "halcyon.py")


def _filtered(n, rho, rng, order=1):
    """Unit-variance errors: white noise through ``order`` (1 or 2) first-order filters of pole ``rho``."""
    if order == 1:
        return lfilter([math.sqrt(1 - rho ** 2)], [1, -rho], rng.standard_normal(n))
    e = lfilter([1.0], [1.0, -rho], lfilter([1.0], [1.0, -rho], rng.standard_normal(n)))
    return e / math.sqrt((1 + rho ** 2) / (1 - rho ** 2) ** 3)   # the stationary variance of the cascade


def ra66m(eps: float, rho: float, seed: int, stated: bool):
    from rocketid.cases import ra66m as spec_of, ra66m_truth
    spec = spec_of()
    truth = with_effects(spec, "thrust_level", {"eps_thrust": eps}) if eps else spec
    clean = ri.simulate_measurements(truth, ra66m_truth(truth), ri.ra66_times(), seed=0,
                                     sigma={"x": 1e-9, "h": 1e-9, "v": 1e-9})
    rng = np.random.default_rng(100 + seed)
    return ri.Measurements(tuple(ri.Channel(c.name, c.times, c.values + _filtered(c.times.size, rho, rng),
                                            1.0 if stated else None) for c in clean.channels)), "ra66m"


def halcyon(eps: float, rho: float, seed: int, stated: bool, order: int = 1):
    import halcyon as V
    from blind_study import truth
    times = 0.1 * np.arange(1, 801)
    out = truth.simulate(times, {"thrust_eps": eps} if eps else {})
    rng = np.random.default_rng(seed)
    return ri.Measurements(tuple(ri.Channel(c, times, out[c] + V.SIGMA[c] * _filtered(times.size, rho, rng, order),
                                            V.SIGMA[c] if stated else None) for c in ("x", "h", "v"))), HALCYON


CASES = {  # name: (maker, thrust error, rho, seed, sigma stated)
    "ra66m-clean-stated": (ra66m, 0.0, 0.9, 0, True),
    "ra66m-clean-estimated": (ra66m, 0.0, 0.9, 0, False),
    "ra66m-thrust-stated": (ra66m, 0.02, 0.9, 1, True),
    "halcyon-clean-stated": (halcyon, 0.0, 0.6, 1, True),
    "halcyon-clean-estimated": (halcyon, 0.0, 0.6, 3, False),
    "halcyon-shortfall-stated": (halcyon, -0.025, 0.6, 2, True),
    "halcyon-shortfall-estimated": (halcyon, -0.025, 0.6, 2, False),
    "halcyon-clean-second-order": (lambda *a: halcyon(*a, order=2), 0.0, 0.8, 1, True),
    "halcyon-shortfall-second-order": (lambda *a: halcyon(*a, order=2), -0.025, 0.8, 2, True),
}


def run(name: str, action: str) -> None:
    maker, eps, rho, seed, stated = CASES[name]
    data, model = maker(eps, rho, seed, stated)
    t0 = time.perf_counter()
    rep = diagnose(data, model, sigma=None if stated else "estimate", workers=1, correlated_noise=action)
    f = rep.final
    est = {k: f"{v:.4g} +- {s:.2g}" for k, (v, s) in f.parameters.items() if k == "eps_thrust"}
    noise = {c: f"{v:.3g}" for c, (v, _) in rep.noise_from_data.items()}
    kept = {c.channel: f"{c.kept}/{c.n_samples} (rho {c.rho:.2f})" for c in rep.correlated_noise.correlated} \
        if rep.correlated_noise else {}
    print(f"{name} [{action}]: {', '.join(f.effects) or '-'} | {f.verdict} | chi2/dof {f.chi2_per_dof:.4g} | "
          f"{est} | noise from data {noise} | correlated (kept/samples) {kept} | {time.perf_counter() - t0:.0f} s", flush=True)


def main(argv: list[str]) -> None:
    warnings.simplefilter("ignore")
    actions = ["thin", "keep"] if "--keep" in argv else ["thin"]
    names = [a for a in argv if not a.startswith("--")] or list(CASES)
    for name in names:
        if name not in CASES:
            raise SystemExit(f"unknown case {name!r}: {', '.join(CASES)}")
        for action in actions:
            run(name, action)


if __name__ == "__main__":
    main(sys.argv[1:])
