"""The free shape (``rocketid.diagnostics.freeshape``) of finished diagnoses, fitted again from their report folders.

    python benchmarks/free_shape_rows.py --model tests/vehicles/wren.py --sigma estimate DIR [DIR ...] [--json OUT]

Each ``DIR`` is a study's case: ``DIR/../<case>.csv`` beside ``DIR = .../report-<case>`` (the study harnesses'
layout) or ``DIR/<case>.csv``. The base model is fitted as ``diagnose`` fits it (wild points dropped, the noise
from the data with ``--sigma estimate``); the search's final effects are read from ``DIR/diagnosis.json`` and
rebuilt by name from the catalogue and its refined shapes for this vehicle, their estimates the start; the kind
is picked as ``diagnose`` picks it (``api._free_shape_kinds``: the kinds of the effects added that have a free
shape, the screen's first candidate's, the thrust's, in turn). Nothing of the search is run again, so a diagnosis made before the free shape existed (or with an
older rule for its kind) gets the free shape the current code would fit. One line per case; ``--json`` keeps them.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace


def _effects_by_name(names, vehicle):
    """The catalogue's effects and their refined shapes (two levels) for ``vehicle``, by name."""
    from rocketid.diagnostics import CATALOGUE
    found, todo = {}, list(CATALOGUE.values())
    for _ in range(3):
        nxt = []
        for e in todo:
            found.setdefault(e.name, e)
            nxt += list(e.refinements(vehicle))
        todo = nxt
    missing = [n for n in names if n not in found]
    if missing:
        raise SystemExit(f"effects not in the catalogue's shapes for this vehicle: {', '.join(missing)}")
    return [found[n] for n in names]


def row(folder: Path, model: str, sigma) -> dict:
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import _free_shape_kinds, base_fit, resolve_model
    from rocketid.diagnostics.freeshape import free_shape_check
    from rocketid.diagnostics.screen import vehicle_of
    from rocketid import read_csv
    diag = json.loads((folder / "diagnosis.json").read_text())
    case = folder.name.removeprefix("report-")
    csv = next((p for p in (folder.parent / f"{case}.csv", folder / f"{case}.csv") if p.is_file()), None)
    if csv is None:
        raise SystemExit(f"no {case}.csv beside {folder}")
    spec, _ = resolve_model(model)
    t0 = time.perf_counter()
    fit, _, counts, _, _ = base_fit(spec, read_csv(csv, spec.output_names), sigma)
    band = noise_band(fit, estimated=counts) if counts else noise_band(fit)
    vehicle = vehicle_of(fit)
    names = list(diag["final"]["effects"])
    effects = _effects_by_name(names, vehicle)
    params = diag["final"]["parameters"]
    final = SimpleNamespace(spec=SimpleNamespace(parameter_names=tuple(params)),
                            p=[params[n]["value"] for n in params])
    disc = SimpleNamespace(base_fit=fit, fit=final, band=band, vehicle=vehicle, effects=tuple(effects))
    ranking = SimpleNamespace(candidates=[SimpleNamespace(name=c["name"], kind=c["kind"]) for c in diag["candidates"][:1]])
    kinds = _free_shape_kinds(disc, ranking)
    # diagnose fits it only when the search ended above the noise (not at a named tie, not cut short)
    above = (kinds and not diag["final"]["fits_to_noise"] and not diag.get("search_stopped")
             and diag["final"]["verdict"] in ("partly explained", "not explained by the catalogue"))
    fs = free_shape_check(disc, *kinds[0], then=kinds[1:]) if above else None
    out = {"case": case, "verdict": diag["final"]["verdict"], "final": names,
           "final_chi2": diag["final"]["chi2_per_dof"], "base_chi2": float(fit.chi2_per_dof),
           "band": float(band.upper), "seconds": time.perf_counter() - t0,
           "free_shape": None if fs is None else fs.to_dict(), "text": "" if fs is None else fs.text()}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--model", required=True)
    ap.add_argument("--sigma", default=None, help="'estimate' to take the noise from the data")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    rows = []
    for folder in a.folders:
        r = row(folder, a.model, a.sigma)
        rows.append(r)
        fs = r["free_shape"]
        print(f"{r['case']}: {r['verdict']} ({' + '.join(r['final']) or 'nothing'}, chi2/dof {r['final_chi2']:.4g}); "
              + ("no free shape" if fs is None else
                 f"free shape {fs['effect']}" + (f" beside {', '.join(fs['kept'])}" if fs["kept"] else " alone")
                 + f" chi2/dof {fs['chi2_per_dof']:.4g} (band <= {r['band']:.4g}), "
                 + ("reaches the noise" if fs["reaches_noise"] else "above the noise")
                 + f"; {fs['reading'] or fs['message']}"
                 + (f"; not needed: {', '.join(fs['not_needed'])}" if fs.get("not_needed") else "")
                 + "".join(f" (tried before: {t['effect']} beside {t['kept'] or 'nothing'}, "
                           + (t['message'] if t['message'] else f"chi2/dof {t['chi2_per_dof']:.4g}") + ")"
                           for t in fs["tried"])) + f" [{r['seconds']:.0f} s]", flush=True)
    if a.json is not None:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
