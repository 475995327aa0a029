"""How often the wild-point test flags a point where there is none: on Gaussian noise, and on every case of
the vehicle studies (``docs/telemetry.md``, "Wild points"); and on the same base fits, whether the errors are
found correlated in time (``rocketid.diagnostics.correlated``; none of the studies' noise is).

::

    python benchmarks/wild_points_scan.py gaussian                  # the false-alarm share, Monte Carlo
    python benchmarks/wild_points_scan.py cost                      # its time beside the base fit's
    python benchmarks/wild_points_scan.py wren sounding air unseen telemetry blind discovery
    python benchmarks/wild_points_scan.py falcon9                   # the two real flights
    python benchmarks/wild_points_scan.py correlated                # the correlated-errors rule on series

A study's data come from its directory (the study's own environment variable, as its ``run.py``; made from
its truth when missing). Each case gets the diagnosis's base fit (``rocketid.diagnostics.api.base_fit``:
the noise from the data where the study estimates it, the study's flight window) and the test; the line
per case names the points flagged. Nothing is diagnosed further.
"""

from __future__ import annotations

import glob
import importlib
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for extra in (ROOT / "tests", ROOT / "tests" / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

from rocketid.cli import flight_window  # noqa: E402
from rocketid.diagnostics.api import _read_data, base_fit, resolve_model  # noqa: E402
from rocketid.diagnostics.wild import LEVEL, series_points  # noqa: E402

STUDIES = {"wren": "wren_study.run", "sounding": "sounding_study.run", "air": "airlaunch_study.run",
           "unseen": "unseen_study.run", "telemetry": "telemetry_study.run"}


def gaussian(reps_small: int = 4000, reps_large: int = 300) -> None:
    """Share of data sets of 3 channels of white unit noise with a point flagged (the level is 1 %)."""
    rng = np.random.default_rng(0)
    for n, reps in ((377, reps_small), (6600, reps_large)):
        t = 0.1 * np.arange(n)
        hits = sum(any(series_points(t, rng.standard_normal(n), n_total=3 * n) for _ in range(3))
                   for _ in range(reps))
        print(f"3 x {n} samples: {hits} of {reps} data sets flagged ({100 * hits / reps:.2f} %; level "
              f"{100 * LEVEL:g} %)", flush=True)


def correlated(white: int = 2000, reps: int = 50) -> None:
    """The correlated-errors rule (``rocketid.diagnostics.correlated.noise_correlation``) on series: how often
    white noise is called correlated, alone and under a smooth 5-sigma misfit; for first-order errors of each
    ``rho``, how often they are found, the stride and the fitted ``rho``; second-order errors; a misfit of a
    short period over part of the flight (a motor's ripple); a 10-sample moving average."""
    import math
    from scipy.signal import lfilter
    from rocketid.diagnostics.correlated import noise_correlation
    rng = np.random.default_rng(5)

    def first_order(n, rho):
        return lfilter([math.sqrt(1 - rho ** 2)], [1, -rho], rng.standard_normal(n))

    for n, dt in ((6600, 0.01), (800, 0.1), (377, 0.1), (1131, 0.2)):
        t = dt * np.arange(n)
        alone = sum(noise_correlation("x", t, rng.standard_normal(n)).correlated for _ in range(white))
        misfit = 5.0 * np.sin(2 * np.pi * t / (t[-1] / 3))
        under = sum(noise_correlation("x", t, misfit + rng.standard_normal(n)).correlated for _ in range(white // 10))
        print(f"{n} samples every {dt} s: white noise called correlated {alone} of {white}; under a smooth 5-sigma "
              f"misfit {under} of {white // 10}", flush=True)
        for rho in (0.1, 0.2, 0.3, 0.6, 0.9, 0.97):
            found = [noise_correlation("x", t, first_order(n, rho)) for _ in range(reps)]
            hit = [c for c in found if c.correlated]
            print(f"  first-order rho {rho}: found {len(hit)} of {reps}"
                  + (f", stride median {np.median([c.stride for c in hit]):g}, rho fitted median "
                     f"{np.median([c.rho for c in hit]):.3f}, settled {sum(c.settled for c in hit)}" if hit else ""),
                  flush=True)
        for rho in (0.6, 0.8):
            found = []
            for _ in range(reps):
                e = lfilter([1.0], [1.0, -rho], lfilter([1.0], [1.0, -rho], rng.standard_normal(n)))
                found.append(noise_correlation("x", t, e / e.std()))
            print(f"  second-order rho {rho}: found {sum(c.correlated for c in found)} of {reps}", flush=True)
        for amp in (1.0, 3.0):
            burn = (t > 0.06 * t[-1]) & (t < 0.31 * t[-1])
            ripple = amp * np.sin(2 * np.pi * t / (12 * dt)) * burn
            hits = sum(noise_correlation("x", t, ripple + rng.standard_normal(n)).correlated for _ in range(reps))
            print(f"  a misfit of 12 samples' period over a quarter of the flight, {amp:g} sigma: called correlated "
                  f"{hits} of {reps}", flush=True)
        ma = [noise_correlation("x", t, np.convolve(rng.standard_normal(n + 9), np.ones(10) / math.sqrt(10), "valid"))
              for _ in range(reps)]
        print(f"  10-sample moving average: found {sum(c.correlated for c in ma)} of {reps}, stride median "
              f"{np.median([c.stride for c in ma if c.correlated] or [1]):g}", flush=True)


def cost(repeats: int = 5) -> None:
    """The test's time against the base fit's, on Stage-30's 19 800 samples (the hidden-effect study's
    s30-thrust_level case; best of ``repeats``, the code cache warm after the first fit)."""
    from discovery_study import harness as H
    from discovery_study.cases import BY_ID
    from rocketid.diagnostics.api import _fit_base
    from rocketid.diagnostics.wild import find_wild_points
    case = BY_ID["s30-thrust_level"]
    spec, _ = resolve_model(H.model_of(case))
    meas, _ = _read_data(str(H.case_data(case)), spec)
    fits, tests = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fit = _fit_base(spec, meas, None, None, None, [])
        t1 = time.perf_counter()
        find_wild_points(fit)
        fits.append(t1 - t0)
        tests.append(time.perf_counter() - t1)
    print(f"{meas.n_samples} samples: the test {min(tests):.3f} s, the base fit {min(fits):.3f} s (best of {repeats})")


CORRELATED: list = []
"""The data sets whose errors the base fit found correlated in time (``rocketid.diagnostics.correlated``)."""


def _line(label: str, name: str, spec, meas, sigma, guess=None) -> bool:
    t0 = time.perf_counter()
    fit, _, _, wild, corr = base_fit(spec, meas, sigma, guess=guess)
    print(f"{label} {name}: {len(wild)} wild, base chi2/dof {fit.chi2_per_dof:.4g}, {time.perf_counter() - t0:.1f} s"
          + (f" -- {wild.note()}" if wild else "") + (f" -- {corr.note()}" if corr else ""), flush=True)
    if corr:
        CORRELATED.append(f"{label} {name}")
    return bool(wild)


def study(key: str) -> tuple[int, int]:
    S = importlib.import_module(STUDIES[key]).STUDY
    spec0, _ = resolve_model(str(S.model_file))
    args = list(S.extra_args)
    sigma = "estimate" if "--sigma" in args else None
    win = flight_window(args[args.index("--window") + 1]) if "--window" in args else None
    flagged = 0
    for case in S.cases:
        spec, guess = spec0, None
        meas, _ = _read_data(str(S.make_data(case)), spec)
        if win is not None:
            from rocketid.start import apply_window, window_guess
            p_full = spec.parameter_vector(None)
            spec_w, meas, _ = apply_window(spec, meas, win, p_full)
            spec, guess = spec_w, window_guess(spec0, spec_w, p_full)
        flagged += _line(key, case.name, spec, meas, sigma, guess)
    return flagged, len(S.cases)


def blind() -> tuple[int, int]:
    """Halcyon-8's cases, as ``tests/blind_study/run.py`` made them (``$ROCKETID_BLIND_DIR``)."""
    folder = os.environ.get("ROCKETID_BLIND_DIR", "/tmp/rocketid-blind")
    files = sorted(glob.glob(os.path.join(folder, "*.csv")))
    if not files:
        raise SystemExit(f"no Halcyon-8 data in {folder}: run tests/blind_study/run.py first (ROCKETID_BLIND_DIR)")
    spec, _ = resolve_model(str(ROOT / "tests" / "vehicles" / "halcyon.py"))
    flagged = sum(_line("blind", Path(f).stem, spec, _read_data(f, spec)[0], None) for f in files)
    return flagged, len(files)


def falcon9() -> tuple[int, int]:
    """The two real Falcon 9 first-stage flights (``rocketid.examples.falcon9``), with their quantization
    sigmas and with the noise from the data."""
    from rocketid.examples.falcon9 import FLIGHTS, falcon9_measurements, falcon9_model
    flagged = n = 0
    for flight in FLIGHTS:
        data = falcon9_measurements(flight)
        spec = falcon9_model(data)
        for sigma in (None, "estimate"):
            flagged += _line("falcon9", f"{flight} (sigma {sigma or 'stated'})", spec, data, sigma)
            n += 1
    return flagged, n


def discovery() -> tuple[int, int]:
    """The hidden-effect study's 49 cases (``$ROCKETID_STUDY_DIR``)."""
    from discovery_study import harness as H
    from discovery_study.cases import ALL
    flagged = 0
    for c in ALL:
        spec, _ = resolve_model(H.model_of(c))
        flagged += _line("discovery", c.id, spec, _read_data(str(H.case_data(c)), spec)[0], None)
    return flagged, len(ALL)


def main(argv: list[str]) -> None:
    warnings.simplefilter("ignore")
    if not argv:
        raise SystemExit(__doc__)
    total = flagged = 0
    for key in argv:
        if key == "gaussian":
            gaussian()
            continue
        if key == "cost":
            cost()
            continue
        if key == "correlated":
            correlated()
            continue
        if key in STUDIES:
            f, n = study(key)
        elif key == "blind":
            f, n = blind()
        elif key == "discovery":
            f, n = discovery()
        elif key == "falcon9":
            f, n = falcon9()
        else:
            raise SystemExit(f"unknown: {key!r} (gaussian, cost, correlated, {', '.join(STUDIES)}, blind, discovery, "
                             "falcon9)")
        flagged, total = flagged + f, total + n
    if total:
        print(f"{flagged} of {total} data sets with a point flagged; {len(CORRELATED)} with errors correlated in time"
              + (f" ({', '.join(CORRELATED)})" if CORRELATED else ""))


if __name__ == "__main__":
    main(sys.argv[1:])
