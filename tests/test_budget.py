"""The diagnosis's time budget (``diagnose(budget=)``, ``rocketid diagnose --budget``).

Truth: the hidden-effect study's own truth model of RA-66 (``tests/discovery_study/truth.py``: a
vector force balance, the thrust scaled in its own expression, the altimeter's bias added to the
simulated readings), flown with the thrust 2 % above the stated one and the altimeter 5 m high --
two effects, found in two steps (thrust, then the bias) when the search has its time.

A search cut short must say so, keep the steps it completed, stop its worker processes, and never
claim more than the model it reached: no "nothing missing", no "not explained by the catalogue" in
words that say the catalogue was tried.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import time

import numpy as np

import pytest
from click.testing import CliRunner

from discovery_study.truth import measure, ra66_vehicle
from rocketid import estimate
from rocketid.cases.ra66 import ra66
from rocketid.cli import main
from rocketid.diagnostics import CATALOGUE
from rocketid.diagnostics.accept import noise_band
from rocketid.diagnostics.refit import BudgetSpent, budget_spent, refit_all, time_budget
from rocketid.diagnostics.screen import vehicle_of
from rocketid.diagnostics import step as S

TRUTH = {"thrust_level": {"eps_thrust": 0.02}, "bias_h": {"b_h": 5.0}}


@pytest.fixture(scope="module")
def data():
    return measure(ra66_vehicle(), TRUTH, seed=401)


@pytest.fixture(scope="module")
def base(data):
    fit = estimate(ra66(), data)
    assert fit.success
    return fit


def _ctx(fit):
    return S._Search(fit.spec, noise_band(fit), vehicle_of(fit), 0.05, None, 60.0, 2, True, None)


def test_a_budget_that_runs_out_stops_the_refits_running_and_starts_none(base):
    ctx = _ctx(base)
    tasks = [ctx.task(base, [CATALOGUE[n]], (n,)) for n in ("wind", "density", "thrust_level", "bias_h")]
    t0 = time.perf_counter()
    with time_budget(0.3):
        with pytest.raises(BudgetSpent):
            refit_all(tasks, workers=2)
        assert budget_spent()
    # the wind's and the density's refits take seconds each; the batch was given up at the budget
    assert time.perf_counter() - t0 < 8.0
    assert not mp.active_children()                     # the workers running were stopped
    assert not budget_spent()                           # outside the block there is no budget
    with time_budget(None):
        assert not budget_spent()


def test_a_search_cut_short_keeps_the_steps_it_completed(base):
    """Step 1 (thrust) given, the budget spent before step 2: the path ends with step 1 and says it stopped at 2."""
    ctx = _ctx(base)
    cands = list(CATALOGUE.values())
    scr = S.screen(base, cands, level=0.05, vehicle=ctx.vehicle)
    i = scr.names.index("thrust_level")
    (refit,) = ctx.refit([ctx.task(base, [scr.contenders[i].effect], ("thrust_level",))])
    accs = [S.accept(refit, ctx.band)] * len(scr.contenders)
    with time_budget(1e-9):
        path = S._forward(ctx, base, cands, 3, [], first=(scr, accs, i))
    assert path.stopped == 2
    assert [s.number for s in path.steps] == [1] and path.steps[0].effects == ("thrust_level",)
    assert [e.name for e in path.chosen] == ["thrust_level"]
    assert 1.0 < path.current.chi2_per_dof < 3.0 and not path.ok     # the bias is still missing


def test_the_report_of_a_search_cut_short_says_where_and_claims_nothing_it_did_not_try(data, tmp_path):
    csv = data.to_csv(tmp_path / "flight.csv")
    out = tmp_path / "diag"
    res = CliRunner().invoke(main, ["diagnose", str(csv), "--model", "ra66", "--max-effects", "2", "--holdout", "none",
                                    "--budget", "0.001", "--out", str(out)])
    assert res.exit_code == 0, res.output
    d = json.loads((out / "diagnosis.json").read_text())
    assert d["search_stopped"] == "the time budget of 0.001 s ran out during step 1 of the search"
    final = d["final"]
    assert final["effects"] == [] and not final["fits_to_noise"]
    assert final["verdict"] != "nothing missing"
    text = final["explanation"]
    assert text.startswith("No effect was added before the search was cut short")
    assert "does not say the catalogue cannot explain it" in text and "--budget" in text
    assert any("Mach-indexed variant of the time-knot drag was not searched" in n for n in d["notes"])
    assert d["variant"] is None


@pytest.mark.parametrize("value", ["0", "-5", "inf"])
def test_a_budget_that_is_not_a_positive_number_of_seconds_is_refused(data, tmp_path, value):
    csv = data.to_csv(tmp_path / "flight.csv")
    res = CliRunner().invoke(main, ["diagnose", str(csv), "--budget", value, "--out", str(tmp_path / "d")])
    assert res.exit_code == 2 and "--budget must be a positive number of seconds" in res.output
    from rocketid.diagnostics.api import diagnose
    from rocketid.errors import SettingsError
    with pytest.raises(SettingsError, match="budget must be a positive number of seconds"):
        diagnose(data, "ra66", budget=float(value))


def test_the_search_reports_its_progress_step_by_step(data):
    """``diagnose(progress=)`` gets a line at each stage: the contenders refitted, the effect taken and the fall."""
    from rocketid.diagnostics.api import diagnose
    lines: list = []
    rep = diagnose(data, "ra66", max_effects=2, holdout=None, variant=False, progress=lines.append)
    assert rep.final.effects == ("thrust_level", "bias_h") and rep.final.verdict == "explained"
    assert all(l.startswith("search ") and " s: " in l for l in lines)
    said = [l.split(" s: ", 1)[1] for l in lines]
    assert said[0].startswith("step 1: ranking the candidates at chi2/dof 58.7")
    assert any(m.startswith("step 1: refitting ") and "thrust_level" in m for m in said)
    taken = [m for m in said if " -- chi2/dof " in m]
    assert len(taken) == 2 and taken[0].startswith("step 1: thrust_level -- chi2/dof 58.7")
    assert taken[1].startswith("step 2: thrust_level, bias_h -- ")
    # the seconds since the search started never go back
    secs = [float(l.split(" s: ", 1)[0].split()[1]) for l in lines]
    assert secs == sorted(secs) and secs[-1] <= rep.discovery.timings["discover_s"] + 1
    # the seconds of each stage tried: the forward search, then the exchange, the finer shape and the simpler
    # shape (two effects, explained); they add up to no more than the search, and the report keeps them
    stages = {k: v for k, v in rep.discovery.timings.items() if k.startswith("search_")}
    assert {"search_forward_s", "search_exchange_s", "search_simpler_shape_s"} <= set(stages), stages
    assert "search_second_path_s" not in stages and sum(stages.values()) <= rep.discovery.timings["discover_s"]
    assert stages["search_forward_s"] > 0.5 * sum(stages.values()) and stages.items() <= rep.timings.items()


# ---- checkpoints: a search stopped or interrupted goes on from the refits it made ---------------------------------

def test_refits_kept_as_checkpoints_are_taken_instead_of_run_and_a_changed_task_is_run(base, tmp_path):
    from rocketid.diagnostics.refit import refit_checkpoints, task_key
    ctx = _ctx(base)
    tasks = [ctx.task(base, [CATALOGUE[n]], (n,)) for n in ("thrust_level", "bias_h")]
    with refit_checkpoints(tmp_path):
        first = refit_all(tasks, workers=2)
    keys = [task_key(t) for t in tasks]
    assert len(set(keys)) == 2 and sorted(p.stem for p in tmp_path.glob("*.pkl")) == sorted(keys)
    t0 = time.perf_counter()
    with refit_checkpoints(tmp_path):
        again = refit_all(tasks, workers=2)
    assert time.perf_counter() - t0 < 2.0                       # read, not refitted
    for a, b in zip(first, again):
        assert a.name == b.name and a.objective == b.objective and a.seconds == b.seconds
        assert np.array_equal(a.p, b.p)
    # another start is another refit: its key differs and it is run (and kept)
    moved = ctx.task(base, [CATALOGUE["thrust_level"]], ("thrust_level",), {"eps_thrust": 0.01})
    assert task_key(moved) not in keys
    with refit_checkpoints(tmp_path):
        (r,) = refit_all([moved], workers=1)
    assert r.success and len(list(tmp_path.glob("*.pkl"))) == 3
    # a torn file is refitted, not trusted
    (tmp_path / f"{keys[0]}.pkl").write_bytes(b"torn")
    with refit_checkpoints(tmp_path):
        (r0,) = refit_all(tasks[:1], workers=1)
    assert r0.objective == pytest.approx(first[0].objective, rel=1e-9)
    # with no folder nothing is kept
    with refit_checkpoints(None):
        refit_all([ctx.task(base, [CATALOGUE["scale_v"]], ("scale_v",))], workers=1)
    assert len(list(tmp_path.glob("*.pkl"))) == 3


def test_a_refit_whose_model_cannot_be_built_fails_as_a_refit_with_checkpoints_on(base, tmp_path):
    """A task whose model cannot be built (here an effect given twice) is a failed refit that says why, with
    checkpoints on as without -- keying it for its checkpoint must not raise and end the whole search (it did
    on Petrel-V, where a refined shape was asked for a second time: 'the discovery failed')."""
    from rocketid.diagnostics.refit import refit_checkpoints, task_key
    ctx = _ctx(base)
    bad = ctx.task(base, [CATALOGUE["bias_h"], CATALOGUE["bias_h"]], ("bias_h",))
    good = ctx.task(base, [CATALOGUE["bias_h"]], ("bias_h",))
    assert task_key(bad) != task_key(good)
    for folder in (tmp_path, None):
        with refit_checkpoints(folder):
            r_bad, r_good = refit_all([bad, good], workers=1)
        assert not r_bad.success and "effect 'bias_h' is given twice" in r_bad.message, r_bad.message
        assert r_good.success


def test_a_diagnosis_stopped_at_its_budget_resumes_from_its_checkpoints_to_the_same_answer(data, tmp_path):
    csv = data.to_csv(tmp_path / "flight.csv")
    # without the refined shapes: the budget and the checkpoints are the search's, whatever its steps refit
    args = ["diagnose", str(csv), "--model", "ra66", "--max-effects", "2", "--holdout", "none", "--no-refine"]
    whole = CliRunner().invoke(main, args + ["--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    ref = json.loads((tmp_path / "whole" / "diagnosis.json").read_text())["final"]
    assert ref["effects"] == ["thrust_level", "bias_h"] and ref["verdict"] == "explained"
    assert not (tmp_path / "whole" / "checkpoints").exists()           # a search that ended leaves none
    # the budget is half of the search's own time on a warm code cache: the first run may have generated the
    # augmented models' code, which a budget taken from its wall time would let the cut run finish within
    warm = CliRunner().invoke(main, args + ["--out", str(tmp_path / "warm")])
    assert warm.exit_code == 0, warm.output
    search_s = json.loads((tmp_path / "warm" / "diagnosis.json").read_text())["timings"]["discover_s"]

    out = tmp_path / "cut"
    cut = CliRunner().invoke(main, args + ["--out", str(out), "--budget", f"{0.5 * search_s:.1f}"])
    assert cut.exit_code == 0, cut.output
    d = json.loads((out / "diagnosis.json").read_text())
    assert d["search_stopped"], "the budget did not stop the search"
    kept = list((out / "checkpoints").glob("*.pkl"))
    assert kept and any(n.startswith("checkpoints: the ") and "--resume" in n for n in d["notes"])

    again = CliRunner().invoke(main, args + ["--out", str(out)])
    assert again.exit_code == 2 and "holds the refits of an unfinished diagnosis" in again.output
    assert "--resume" in again.output

    resumed = CliRunner().invoke(main, args + ["--out", str(out), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    final = json.loads((out / "diagnosis.json").read_text())["final"]
    assert final["effects"] == ref["effects"] and final["verdict"] == ref["verdict"]
    assert final["chi2_per_dof"] == pytest.approx(ref["chi2_per_dof"], rel=1e-6)
    for n, v in ref["parameters"].items():
        assert final["parameters"][n]["value"] == pytest.approx(v["value"], rel=1e-6, abs=1e-9), n
    assert not (out / "checkpoints").exists()                          # ended: removed
