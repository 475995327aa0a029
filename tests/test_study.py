"""The chapter's study on RA-66 (Tables 7.1-7.3), shortened, and `rocketid reproduce`."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from rocketid.cli import main
from rocketid.errors import SettingsError
from rocketid.study import StudySettings, reproduce, run_seeds

NAMES = ["CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL"]


def _read(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    return out, reproduce(out, runs=2, n_iter=10, n_perturbations=4, executor="serial", progress=False)


def test_least_eta_run_predicts_better_than_index_0(study):
    _, res = study
    assert res.sampling.estimability.n_estimated == 5            # scaling "nominal", like the chapter
    assert res.best_index in (1, 2)
    assert res.eta[res.best_index] == np.nanmin(res.eta[1:]) < res.eta[0]
    assert res.best_beats_index0                                   # Table 7.2, on x, h and v
    assert np.all(res.errors[1:] < res.errors[0])                 # every run, like the chapter
    # Table 7.3: starts with v0 < 0 pass through the singular v = 0 (rounding decides the direction)
    regular = ~res.perturbed_singular
    assert regular.any() and res.best_beats_index0_perturbed[regular].all()
    assert all(v > 1 for v in res.improvement.values())


def test_tables_written_as_specified(study):
    out, res = study
    cols, rows = _read(out / "table_7_1.csv")
    assert cols == ["index", *NAMES, "eta"] and [r[0] for r in rows] == ["0", "1", "2"]
    np.testing.assert_array_equal(np.array(rows, float)[:, 1:9], res.estimates)
    cols, rows = _read(out / "table_7_2.csv")
    assert cols == ["index", "x", "h", "v"] and [r[0] for r in rows] == ["0", "1", "2"]
    np.testing.assert_array_equal(np.array(rows, float)[:, 1:], res.errors)
    cols, rows = _read(out / "table_7_3.csv")
    assert cols == ["case", "x0", "h0", "v0", "index", "x", "h", "v"]
    assert [(r[0], r[4]) for r in rows] == [(str(c), i) for c in range(1, 5) for i in ("0", str(res.best_index))]
    for name in ("tables.md", "summary.txt", "study.json", "predictions.png", "eta.png"):
        assert (out / name).stat().st_size > 0
    md = (out / "tables.md").read_text()
    assert "scaling nominal" in md and "0.014094" in md and "| 0 |" in md
    d = json.loads((out / "study.json").read_text())
    assert d["settings"]["run_seeds"] == [1, 2] and d["np"] == 5


def test_reference_row_is_q2_fixed_at_p0(study):
    _, res = study
    est = res.sampling.estimability
    import rocketid as ri
    np.testing.assert_allclose(est.q2_of(res.estimates[0]), est.q2_of(ri.ra66().guess), atol=1e-9)


def test_summary_and_notes(study):
    _, res = study
    text = res.summary().text()
    for part in ("Table 7.1", "Table 7.2", "Table 7.3", "Beside the chapter", "shortened", "np = 5"):
        assert part in text


def test_settings_checked():
    assert run_seeds(2, 3) == [2001, 2002, 2003]
    with pytest.raises(SettingsError, match="runs"):
        StudySettings(runs=0)
    with pytest.raises(SettingsError, match="resume"):
        reproduce(None, runs=1, n_iter=1, resume=True)


def test_cli_reproduce_short(tmp_path):
    out = tmp_path / "s"
    r = CliRunner().invoke(main, ["reproduce", "--out", str(out), "--runs", "1", "--n-iter", "3", "--executor",
                                  "serial", "--perturbations", "1", "--no-plots", "--quiet"])
    assert r.exit_code == 0, r.output
    assert "Table 7.1" in r.output and (out / "table_7_1.csv").is_file() and not (out / "eta.png").exists()
    cols, rows = _read(out / "table_7_2.csv")
    assert cols == ["index", "x", "h", "v"] and len(rows) == 2
    # the same again resumes from the finished checkpoint: nothing to redo, same table
    r2 = CliRunner().invoke(main, ["reproduce", "--out", str(out), "--runs", "1", "--n-iter", "3", "--executor",
                                   "serial", "--perturbations", "1", "--no-plots", "--quiet", "--resume"])
    assert r2.exit_code == 0, r2.output
    assert _read(out / "table_7_2.csv") == (cols, rows)


def test_cli_reproduce_bad_input(tmp_path):
    r = CliRunner().invoke(main, ["reproduce", "--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:1"])
    assert r.exit_code == 2 and "--scheduler" in r.output
    r = CliRunner().invoke(main, ["reproduce", "--out", str(tmp_path), "--runs", "0"])
    assert r.exit_code == 2
