"""eta (7.10) and the sampling algorithm (steps 1-10): criterion, stopping rule,
seeding, failures, checkpoint/resume (an exception and a SIGKILL midway), and
the parallel runners (processes; dask with a local cluster on loopback) against
the serial one."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import replace

import numpy as np
import pytest
import scipy.stats as st

import rocketid as ri
from rocketid.errors import DataError, SettingsError, SolverError
from rocketid.sampling import (SamplingSettings, prepare_sampling, sample, statistic_criterion, TERM_NAMES)
from rocketid.sampling import worker as worker_mod
from rocketid.sampling.checkpoint import RunState, checkpoint_path
from rocketid.sampling.worker import DrawOutcome, trial_parameters

SEEDS = [1, 2, 3]
N_ITER = 5


# ---------------------------------------------------------------------------
# eta (7.10)
# ---------------------------------------------------------------------------


def _direct(e):
    """The terms of (7.10) from scipy.stats (sigma = 1)."""
    s1 = st.moment(e, 3, center=0)
    k1 = st.moment(e, 4, center=0)
    s2 = st.skew(e, bias=True)
    k2 = st.kurtosis(e, fisher=False, bias=True)
    return s1, k1, s2, k2


def test_eta_small_for_gaussian_and_grows_for_skewed_or_heavy_tails():
    rng = np.random.default_rng(42)
    n = 20000
    gauss = statistic_criterion(rng.normal(0, 1, n))
    assert gauss.eta < 0.2  # about sqrt(96/n) per kurtosis term
    skewed = statistic_criterion(rng.exponential(1.0, n) - 1.0)            # mean 0, variance 1, skewness 2
    heavy = statistic_criterion(rng.standard_t(5, n) / np.sqrt(5 / 3))     # variance 1, kurtosis 9
    wide = statistic_criterion(rng.normal(0, 2, n))                         # the stated sigma is wrong
    biased = statistic_criterion(rng.normal(0.5, 1, n))                     # a bias
    for c in (skewed, heavy, wide, biased):
        assert c.eta > 10 * gauss.eta
    assert skewed.terms[0] > 1.5 and heavy.terms[1] > 3


def test_eta_terms_match_scipy_and_pool_channels_by_sigma():
    rng = np.random.default_rng(7)
    rx, rh, rv = rng.normal(0, 2, 3000), rng.gamma(2.0, 1.0, 2000) - 2.0, rng.standard_t(4, 1000)
    crit = statistic_criterion({"x": rx, "h": rh, "v": rv}, {"x": 2.0, "h": 1.0, "v": 0.5})
    e = np.concatenate([rx / 2.0, rh, rv / 0.5])
    s1, k1, s2, k2 = _direct(e)
    assert (crit.s1, crit.k1, crit.s2, crit.k2) == pytest.approx((s1, k1, s2, k2), rel=1e-12)
    terms = (abs(s1), abs(k1 - 3), abs(s1 - s2), abs(k1 - k2))
    assert crit.terms == pytest.approx(terms, rel=1e-12)
    assert crit.eta == pytest.approx(sum(terms), rel=1e-12)
    d = crit.as_dict()
    assert [d[k] for k in TERM_NAMES] == pytest.approx(terms, rel=1e-12) and d["eta"] == crit.eta
    assert crit.n == e.size and "eta" in crit.summary().text()


def test_eta_bad_input():
    with pytest.raises(DataError, match="sigma"):
        statistic_criterion({"x": [1.0, 2.0]}, {"h": 1.0})
    with pytest.raises(DataError, match="at least one"):
        statistic_criterion([])
    assert not statistic_criterion([1.0, np.nan, 2.0]).finite


# ---------------------------------------------------------------------------
# The stopping rule and failures, on synthetic outcomes
# ---------------------------------------------------------------------------


def _outcome(k, eta, success=True, seed=1):
    return DrawOutcome(seed, k, success, 0 if success else -1, "ok" if success else "injected", eta,
                       (0.0, 3.0, 0.0, 3.0), 1.0, 3, (0.5,), (0.1,), (0.5,), 0.01)


def test_stopping_rule_counts_n_iter_draws_without_improvement():
    etas = [5.0, 4.0, 6.0, 3.0, 7.0, 8.0, 9.0, 2.5, 9.0, 9.0, 9.0, 1.0]
    stt = RunState(1)
    for k, e in enumerate(etas, 1):
        stt.process(_outcome(k, e), n_iter=3, max_draws=None)
        if stt.stopped_by:
            break
    # improvements at 1, 2, 4; draws 5, 6, 7 do not improve: stop after draw 7 = 4 + n_iter
    assert stt.draws == 7 and stt.stopped_by == "n_iter" and stt.best.draw == 4
    assert stt.improvements == [1, 2, 4]


def test_failed_draws_never_win_and_count_as_no_improvement():
    stt = RunState(1)
    seq = [(3.0, True), (0.0, False), (math.nan, False), (2.0, True), (1.0, False), (9.0, True), (9.0, True)]
    for k, (e, ok) in enumerate(seq, 1):
        stt.process(_outcome(k, e, ok), n_iter=3, max_draws=None)
        if stt.stopped_by:
            break
    assert stt.best.draw == 4 and stt.best.eta == 2.0
    assert [f[0] for f in stt.failures] == [2, 3, 5] and all(f[1] == -1 for f in stt.failures)
    assert stt.draws == 7 and stt.stopped_by == "n_iter"
    assert math.isnan(stt.history[1]) and math.isnan(stt.history[4])


def test_max_draws_cap():
    stt = RunState(1)
    for k in range(1, 5):
        stt.process(_outcome(k, 10.0 - k), n_iter=100, max_draws=4)
    assert stt.stopped_by == "max_draws" and stt.draws == 4


def test_settings_are_checked():
    with pytest.raises(SettingsError, match="n_iter"):
        SamplingSettings(n_iter=0)
    with pytest.raises(SettingsError, match="uniform"):
        SamplingSettings(distribution="gaussian")
    with pytest.raises(SettingsError, match="scaling"):
        SamplingSettings(scaling="log")
    with pytest.raises(SettingsError, match="IPOPT option"):
        SamplingSettings(ipopt={"max_itr": 3})


# ---------------------------------------------------------------------------
# The loop on RA-66
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def problem(ra66_spec, ra66_noisy):
    prepared = ri.prepare(ra66_spec, ra66_noisy)
    return prepare_sampling(prepared, settings=SamplingSettings(n_iter=N_ITER))


@pytest.fixture(scope="module")
def serial(problem):
    return sample(problem, seeds=SEEDS, executor="serial", progress=False)


def _same_runs(a, b):
    """Bit-identical runs: best draw, eta, p, draw count, history, failures."""
    assert len(a.runs) == len(b.runs)
    for ra, rb in zip(a.runs, b.runs):
        assert ra.seed == rb.seed and ra.n_draws == rb.n_draws and ra.stopped_by == rb.stopped_by
        assert ra.best.draw == rb.best.draw
        assert ra.best.eta == rb.best.eta and ra.best.p == rb.best.p and ra.best.q2 == rb.best.q2
        np.testing.assert_array_equal(ra.history, rb.history)
        assert [f[:2] for f in ra.failures] == [f[:2] for f in rb.failures]


def test_steps_1_to_4(problem):
    est = problem.estimability
    assert est.n_estimated == 5 and est.scaling.value == "nominal"   # like the chapter
    ref = problem.reference_outcome
    assert ref.draw == 0 and ref.success and ref.eta > 0
    np.testing.assert_allclose(ref.q2, est.q2_of(ri.ra66().guess))


def test_serial_loop_follows_the_rule(serial, problem):
    assert serial.executor == "serial" and serial.n_wasted == 0
    for r in serial.runs:
        assert r.stopped_by == "n_iter"
        assert r.n_draws == r.improvements[-1] + N_ITER       # n_iter draws in a row without improvement
        finite = np.where(np.isfinite(r.history), r.history, np.inf)
        assert r.best.eta == finite.min() and r.best.draw == int(np.argmin(finite)) + 1
        assert r.best.eta < problem.reference_outcome.eta
    assert serial.n_evaluated == serial.n_draws
    text = serial.summary().text()
    assert "scaling       : nominal" in text and "Runs" in text


def test_draws_are_seeded(problem):
    spec = problem.prepared.spec
    a = trial_parameters(problem.recipe, 5, 3)
    np.testing.assert_array_equal(a, np.random.default_rng([5, 3]).uniform(spec.lower, spec.upper))
    assert not np.array_equal(a, trial_parameters(problem.recipe, 5, 4))
    assert not np.array_equal(a, trial_parameters(problem.recipe, 6, 3))


def test_same_seed_same_result_any_batch_size(problem, serial):
    again = sample(problem, seeds=SEEDS[:2], executor="serial", progress=False,
                   settings=replace(problem.settings, batch_size=1))
    _same_runs(again, replace(serial, runs=serial.runs[:2]))


def test_failures_are_recorded_counted_and_never_win(problem, serial, monkeypatch):
    """Inject a failed solve at the draw that wins in the clean run, and an
    exception at another: both are recorded and the run goes on."""
    clean = serial.runs[0]
    seed, win = clean.seed, clean.best.draw
    q2_fail = problem.estimability.q2_of(trial_parameters(problem.recipe, seed, win))
    q2_raise = problem.estimability.q2_of(trial_parameters(problem.recipe, seed, 1))
    real = worker_mod.estimate_q1

    def flaky(prepared, est, q2, **kw):
        if np.array_equal(q2, q2_raise):
            raise SolverError("injected solver error")
        fit = real(prepared, est, q2, **kw)
        if np.array_equal(q2, q2_fail):
            return replace(fit, success=False, status=-1, message="injected: Maximum Number of Iterations Exceeded")
        return fit

    monkeypatch.setattr(worker_mod, "estimate_q1", flaky)
    worker_mod._CONTEXTS.clear()
    res = sample(problem, seeds=[seed], executor="serial", progress=False)
    worker_mod._CONTEXTS.clear()
    r = res.runs[0]
    assert [(f[0], f[1]) for f in r.failures] == [(1, None), (win, -1)]
    assert "injected solver error" in r.failures[0][2]
    finite = np.where(np.isfinite(r.history), r.history, np.inf)
    assert r.best.draw != win and r.best.eta == finite.min()
    assert math.isnan(r.history[0]) and math.isnan(r.history[win - 1])
    # failures count as "no improvement": the run ends n_iter draws after its last improvement
    assert r.n_draws == r.improvements[-1] + N_ITER
    assert res.n_failures == 2 and "failed" in res.summary().text()


# ---------------------------------------------------------------------------
# Checkpoint and resume
# ---------------------------------------------------------------------------


def test_resume_after_an_exception_midway_equals_an_uninterrupted_run(problem, serial, tmp_path):
    settings = replace(problem.settings, batch_size=2)

    class Stop(Exception):
        pass

    def boom(seed, draws):
        if draws >= 4:
            raise Stop

    with pytest.raises(Stop):
        sample(problem, seeds=[SEEDS[0]], settings=settings, executor="serial", checkpoint_dir=tmp_path,
               progress=False, callback=boom)
    saved = json.loads(checkpoint_path(tmp_path, SEEDS[0]).read_text())
    assert 4 <= saved["draws"] < serial.runs[0].n_draws and saved["stopped_by"] is None
    with pytest.raises(SettingsError, match="unfinished"):
        sample(problem, seeds=[SEEDS[0]], settings=settings, checkpoint_dir=tmp_path, progress=False)
    resumed = sample(problem, seeds=[SEEDS[0]], settings=settings, executor="serial", checkpoint_dir=tmp_path,
                     resume=True, progress=False)
    assert resumed.runs[0].resumed_from == saved["draws"]
    _same_runs(resumed, replace(serial, runs=serial.runs[:1]))
    assert resumed.n_evaluated == serial.runs[0].n_draws - saved["draws"]   # nothing lost, nothing redone


def test_resume_refuses_another_problem_and_extends_n_iter(ra66_spec, ra66_noisy, problem, serial, tmp_path):
    sample(problem, seeds=[SEEDS[1]], executor="serial", checkpoint_dir=tmp_path, progress=False)
    other = prepare_sampling(problem.prepared, settings=SamplingSettings(n_iter=N_ITER, threshold=2000.0))
    with pytest.raises(SettingsError, match="another problem|settings"):
        sample(other, seeds=[SEEDS[1]], checkpoint_dir=tmp_path, resume=True, progress=False)
    # a finished run extended to a larger n_iter = a fresh run with that n_iter
    longer = replace(problem.settings, n_iter=N_ITER + 3)
    ext = sample(problem, seeds=[SEEDS[1]], settings=longer, executor="serial", checkpoint_dir=tmp_path,
                 resume=True, progress=False)
    fresh = sample(problem, seeds=[SEEDS[1]], settings=longer, executor="serial", progress=False)
    _same_runs(ext, fresh)


KILL_SCRIPT = textwrap.dedent("""
    import sys, time
    import rocketid as ri
    from rocketid.sampling import SamplingSettings, prepare_sampling, sample
    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    problem = prepare_sampling(ri.prepare(spec, data), settings=SamplingSettings(n_iter={n_iter}, batch_size=2))
    print("ready", flush=True)
    sample(problem, seeds=[{seed}], executor="serial", checkpoint_dir=sys.argv[1], progress=False,
           callback=lambda s, d: time.sleep(0.4))
    print("finished", flush=True)
""")


def test_sigkill_midway_then_resume_equals_uninterrupted(problem, serial, tmp_path):
    seed = SEEDS[2]
    script = tmp_path / "run.py"
    script.write_text(KILL_SCRIPT.format(n_iter=N_ITER, seed=seed))
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    path = checkpoint_path(tmp_path, seed)
    draws = 0
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if path.is_file():
                draws = json.loads(path.read_text())["draws"]   # always a whole file (atomic replace)
                if draws >= 4:
                    break
            time.sleep(0.02)
        assert proc.poll() is None, f"the run ended before it could be killed: {proc.communicate()}"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    saved = json.loads(path.read_text())
    assert 4 <= saved["draws"] < serial.runs[2].n_draws
    resumed = sample(problem, seeds=[seed], settings=replace(problem.settings, batch_size=2), executor="serial",
                     checkpoint_dir=tmp_path, resume=True, progress=False)
    _same_runs(resumed, replace(serial, runs=serial.runs[2:3]))


# ---------------------------------------------------------------------------
# Parallel runners give the serial result
# ---------------------------------------------------------------------------


def test_process_pool_matches_serial(problem, serial):
    par = sample(problem, seeds=SEEDS, executor="processes", workers=2, progress=False)
    assert par.executor == "processes" and par.workers == 2
    _same_runs(par, serial)
    assert par.n_evaluated == par.n_draws + par.n_wasted
    # each worker that ran a batch reports its set-up (the NLP, the KKT factors, the learnt
    # surface: about 1 s); in a run this short the worker set up first may run every batch
    assert 1 <= len(par.worker_setup_s) <= 2 and all(t < 30 for t in par.worker_setup_s)


def test_dask_local_cluster_matches_serial(problem, serial):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        par = sample(problem, seeds=SEEDS, executor="dask", client=client, progress=False)
        # no task may still run when sample() returns: a speculative batch "cancelled" while it ran
        # on a worker kept running, and the cluster's shutdown then failed now and then
        assert not any(client.processing().values()), client.processing()
        assert par.n_cancelled == 0
    assert par.executor == "dask" and par.workers == 2
    _same_runs(par, serial)


def test_a_worker_with_other_code_refuses(problem):
    from rocketid.errors import RocketidError
    other = replace(problem.recipe, code="0" * 16, token="other-code")
    with pytest.raises(RocketidError, match="other rocketid code"):
        worker_mod.evaluate_batch(other, 1, 1, 2)
    worker_mod._CONTEXTS.pop("other-code", None)


def test_unknown_executor(problem):
    with pytest.raises(SettingsError, match="serial, processes, dask"):
        sample(problem, seeds=[1], executor="threads", progress=False)
