"""The Lagrangian Hessian's structure on a model whose outputs are nonlinear in many samples' states.

RA-66M (19 800 samples) with ``time_offset_2``: every sample's output depends on the time offset, so the
expansion ``M^T Q M`` gives about 15 million entries on some 23 000 places. Their duplicates are merged once per
NLP built (every refit of such a model); this times that build -- ``prepare`` and the first Hessian structure --
with the dense-marker merge (``nlp.DENSE_KEYS``, the default) against ``numpy.unique`` (``DENSE_KEYS = 0``),
alternating, in one run.

    PYTHONPATH=src python3 benchmarks/bench_hessian_structure.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import rocketid as ri
from rocketid import nlp
from rocketid.cases import ra66m, ra66m_truth
from rocketid.diagnostics import with_effects
from rocketid.output import environment_line
from rocketid.solve import prepare


def build(spec, data) -> tuple[float, int]:
    t = time.perf_counter()
    prep = prepare(spec, data)
    rows = prep.nlp.hessianstructure()[0]
    return time.perf_counter() - t, len(rows)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    truth = with_effects(ra66m(), "thrust_level", {"eps_thrust": 0.02})
    data = ri.simulate_measurements(truth, ra66m_truth(truth), ri.ra66_times(), seed=3)
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.screen import vehicle_of
    base = ri.estimate(ra66m(), data)
    shape = next(r for r in CATALOGUE["time_offset"].refinements(vehicle_of(base)) if r.name == "time_offset_2")
    spec = with_effects(ra66m(), [shape])
    build(spec, data)                                     # code generated and cached
    dense = nlp.DENSE_KEYS
    times = {"dense marker": [], "numpy.unique": []}
    nnz = set()
    for _ in range(args.repeat):
        for label, limit in (("dense marker", dense), ("numpy.unique", 0)):
            nlp.DENSE_KEYS = limit
            s, n = build(spec, data)
            times[label].append(s)
            nnz.add(n)
    nlp.DENSE_KEYS = dense
    print(environment_line())
    print(f"RA-66M + time_offset_2, {sum(c.values.size for c in data.channels)} samples, Hessian non-zeros {nnz}")
    for label, t in times.items():
        print(f"  {label:13s} prepare + Hessian structure: median {np.median(t):.2f} s (runs {', '.join(f'{x:.2f}' for x in t)})")
    print(f"  ratio dense / unique: {np.median(times['dense marker']) / np.median(times['numpy.unique']):.2f}")


if __name__ == "__main__":
    main()
