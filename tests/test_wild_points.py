"""Wild points (``rocketid.diagnostics.wild``): isolated samples no model can follow, found on the base fit's
residuals and dropped before the diagnosis.

The end-to-end checks use Wren-H's GPS log made by its own simulator (``tests/wren_study/truth.py``: a
hybrid motor, Cartesian flight, its own atmosphere, nothing shared with rocketid's equations), with the
glitches a GPS receiver makes written in: a multipath jump in altitude, a downrange jump, a speed spike.
The series checks hold the rule to its stated false-alarm level on Gaussian noise and show what it must
leave alone (a step, a segment, a kink, a minimum, a trend to the end, a stretch of larger noise).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
for extra in (HERE, HERE / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import wren as V  # noqa: E402

import rocketid as ri  # noqa: E402
from rocketid.diagnostics import diagnose  # noqa: E402
from rocketid.diagnostics.wild import LEVEL, series_points, threshold  # noqa: E402
from rocketid.errors import SettingsError  # noqa: E402
from wren_study import truth  # noqa: E402
from wren_study.cases import Hidden  # noqa: E402

#: (channel, index among the channel's samples, jump in the channel's units): what a GPS log shows
GLITCHES = (("h", 120, 40.0), ("x", 250, -15.0), ("v", 300, 3.0))
STATED = {"x": V.SIGMA["x"], "h": V.SIGMA["h"], "v": V.SIGMA["v"]}


def _glitched(seed: int = 320):
    data = truth.measurements(Hidden(), seed=seed)
    chans, times = [], {}
    for c in data.channels:
        y = np.array(c.values)
        for name, i, jump in GLITCHES:
            if name == c.name:
                y[i] += jump
                times[name] = float(c.times[i])
        chans.append(ri.Channel(c.name, c.times, y))
    return data, ri.Measurements(tuple(chans)), times


@pytest.fixture(scope="module")
def wren():
    return V.build_model()


@pytest.fixture(scope="module")
def logs():
    return _glitched()


# ---------------------------------------------------------------------------------------------------------
# the rule on series
# ---------------------------------------------------------------------------------------------------------


def test_clean_gaussian_noise_flags_at_the_stated_level():
    """Gaussian noise, 3 channels of 377 samples (Wren-H's log): the share of data sets with any point flagged
    is the level's (1 %; measured 0.85 % on 2000 data sets), here within a generous 3 % on 300."""
    rng = np.random.default_rng(11)
    t = 0.1 * np.arange(377)
    hits = sum(any(series_points(t, rng.standard_normal(t.size), n_total=3 * t.size) for _ in range(3))
               for _ in range(300))
    assert LEVEL == 0.01
    assert hits / 300 <= 0.03, hits


@pytest.mark.parametrize("where, jumps", [
    ((60,), (9.0,)),                     # one spike
    ((150, 151), (12.0, 12.0)),          # two side by side
    ((300, 301, 302), (-15.0, -15.0, -15.0)),  # three side by side
    ((100, 101), (10.0, -10.0)),         # a spike and its rebound
])
def test_spikes_are_found_where_they_are(where, jumps):
    rng = np.random.default_rng(3)
    t = 0.1 * np.arange(377)
    e = rng.standard_normal(t.size) + 20.0 * np.sin(t / 5.0)        # on a misfit that is smooth in time
    for i, j in zip(where, jumps):
        e[i] += j
    found = series_points(t, e, n_total=3 * t.size)
    assert [i for i, _ in found] == list(where)
    assert all(np.sign(z) == np.sign(j) for (_, z), j in zip(found, jumps))


@pytest.mark.parametrize("shape", ["step", "segment", "kink", "minimum", "trend to the end", "larger noise"])
def test_what_is_not_a_wild_point(shape):
    """Residual shapes a missing effect or a sensor makes that are not isolated samples: none is flagged."""
    rng = np.random.default_rng(5)
    t = 0.1 * np.arange(377)
    e = rng.standard_normal(t.size)
    k = np.arange(t.size)
    if shape == "step":                  # a sensor that switches and stays
        e[150:] += 30.0
    elif shape == "segment":             # a 2 s GPS solution jump, then back
        e[150:170] += 30.0
    elif shape == "kink":                # a thrust knee: the slope of the residual changes at one sample
        e += 4.0 * np.abs(k - 180)
    elif shape == "minimum":             # a residual with a sharp smooth minimum (Wren-H's hot tank at 8.4 s)
        e += 0.25 * (k - 180.0) ** 2
    elif shape == "trend to the end":    # a misfit growing fast to the end of the data
        e += 1e-3 * k ** 2.5
    else:                                # engine vibration: the noise 4 times larger from the middle on
        e[190:] *= 4.0
    assert series_points(t, e, n_total=3 * t.size) == []


def test_the_limit_is_bonferroni_over_the_samples():
    from scipy.stats import norm
    assert threshold(1131) == pytest.approx(norm.isf(0.01 / 2262))
    assert 4.4 < threshold(1131) < threshold(19800) < 5.1


# ---------------------------------------------------------------------------------------------------------
# in the diagnosis
# ---------------------------------------------------------------------------------------------------------


def test_a_gps_log_with_glitches_is_diagnosed_without_them(wren, logs):
    """With the noise stated, three glitches take a right model above its noise band (a false alarm: "not
    explained by the catalogue"); the diagnosis finds exactly them, drops them and finds nothing missing."""
    clean, glitched, times = logs
    kept = diagnose(glitched, wren, sigma=STATED, wild_points="keep", workers=1)
    assert sorted((p.channel, p.time) for p in kept.wild_points.points) == sorted(times.items())
    assert kept.final.verdict != "nothing missing"
    assert "kept" in kept.wild_points.note()

    rep = diagnose(glitched, wren, sigma=STATED, workers=1)
    found = {(p.channel, p.time): p for p in rep.wild_points.points}
    assert sorted(found) == sorted(times.items())
    for name, i, jump in GLITCHES:
        p = found[(name, times[name])]
        assert np.sign(p.residual) == -np.sign(jump)               # residual = model - measured
        assert abs(p.residual) == pytest.approx(abs(jump), abs=4 * STATED[name])
    assert rep.final.verdict == "nothing missing", rep.verdict()
    assert rep.fit.prepared.measurements.n_samples == clean.n_samples - 3
    assert rep.wild_points.chi2_with == pytest.approx(kept.fit.chi2_per_dof)
    assert rep.fit.chi2_per_dof < rep.wild_points.chi2_with
    assert rep.verdict()[0].startswith("3 wild point(s)")
    d = rep.to_dict()["wild_points"]
    assert d["action"] == "drop" and len(d["points"]) == 3 and d["chi2_per_dof_with"] > 1.1


def test_the_noise_from_the_data_is_taken_without_them(wren, logs):
    """With the noise estimated from the data, the glitches inflate it (the speed's by 15 %: 0.282 for the
    clean log's 0.244); dropped, the estimate is the clean log's to 2 %."""
    clean, glitched, _ = logs
    from rocketid.data import difference_noise
    rep = diagnose(glitched, wren, sigma="estimate", workers=1, confirm_top=0)
    assert len(rep.wild_points) == 3
    for name in ("x", "h", "v"):
        inflated = difference_noise(glitched[name])[0]
        assert rep.noise_from_data[name][0] == pytest.approx(difference_noise(clean[name])[0], rel=0.02)
        assert rep.noise_from_data[name][0] < inflated


def test_clean_data_have_none(wren, logs):
    clean, _, _ = logs
    rep = diagnose(clean, wren, sigma=STATED, workers=1, confirm_top=0)
    assert not rep.wild_points and rep.wild_points.points == ()
    assert rep.fit.prepared.measurements.n_samples == clean.n_samples
    assert not any("wild point" in line for line in rep.verdict())


def test_the_command_line_lists_them(wren, logs, tmp_path):
    from click.testing import CliRunner

    from rocketid.cli import main as cli
    _, glitched, times = logs
    csv = glitched.to_csv(tmp_path / "gps.csv")
    out = tmp_path / "report"
    res = CliRunner().invoke(cli, ["diagnose", str(csv), "--model", str(HERE / "vehicles" / "wren.py"), "--out",
                                   str(out), "--workers", "1", "--confirm", "0", "--wild-points", "keep",
                                   *[a for n, s in STATED.items() for a in ("--sigma", f"{n}={s}")]])
    assert res.exit_code in (0, 1), res.output
    assert "3 wild point(s)" in res.output and "kept (--wild-points keep)" in res.output
    d = json.loads((out / "diagnosis.json").read_text())["wild_points"]
    assert d["action"] == "keep" and sorted((p["channel"], p["t"]) for p in d["points"]) == sorted(times.items())
    assert "Wild points" in (out / "summary.txt").read_text()


def test_a_bad_setting_is_refused(wren, logs):
    _, glitched, _ = logs
    with pytest.raises(SettingsError, match="wild_points must be one of drop, keep"):
        diagnose(glitched, wren, sigma=STATED, wild_points="remove")


def test_dropping_matches_by_time_so_a_window_cut_keeps_them_apart(wren, logs):
    """The points name samples by channel and time: dropped from the data before a flight window cut them (the
    joint fit of several flights does so) they remove the same samples."""
    _, glitched, times = logs
    rep = diagnose(glitched, wren, sigma=STATED, workers=1, confirm_top=0)
    cut = glitched.window(10.0, 40.0)
    less = rep.wild_points.without(cut)
    for c in cut.channels:
        gone = set(c.times) - set(less[c.name].times)
        assert gone == ({times[c.name]} if 10.0 <= times[c.name] <= 40.0 else set())


def test_the_fit_command_warns_of_them_and_keeps_them(logs, tmp_path):
    """`rocketid estimate` fits the data as given and says which samples look wild (FIT.json lists them)."""
    from click.testing import CliRunner

    from rocketid.cli import main as cli
    _, glitched, times = logs
    csv = glitched.to_csv(tmp_path / "gps.csv")
    fit_json = tmp_path / "fit.json"
    res = CliRunner().invoke(cli, ["estimate", str(csv), "--model", str(HERE / "vehicles" / "wren.py"), "--out",
                                   str(fit_json), *[a for n, s in STATED.items() for a in ("--sigma", f"{n}={s}")]])
    assert res.exit_code == 0, res.output
    assert "Warning: 3 sample(s) look like wild points" in res.output and "The fit keeps them" in res.output
    d = json.loads(fit_json.read_text())
    assert sorted((p["channel"], p["t"]) for p in d["wild_points"]) == sorted(times.items())


def test_several_flights_leave_out_each_flights_wild_points(wren, logs):
    """Two GPS logs of the same rocket, one with the glitches: each flight's diagnosis finds its own, and the
    joint fit of the flights leaves out the ones dropped (matched by channel and time)."""
    from rocketid.commands.diagnose_flights import diagnose_flights
    clean, glitched, times = logs
    other = truth.measurements(Hidden(), seed=321)
    res = diagnose_flights([glitched, other], ["glitched", "clean"], wren, sigma=STATED, confirm_top=0, workers=1)
    first, second = res.reports
    assert sorted((p.channel, p.time) for p in first.wild_points.points) == sorted(times.items())
    assert not second.wild_points
    assert res.joint is not None and res.joint.success
    used = [f.prepared.measurements.n_samples for f in res.joint.flights]
    assert used == [glitched.n_samples - 3, other.n_samples]


def test_the_joint_fit_command_warns_of_each_flights_wild_points(logs, tmp_path):
    """`rocketid estimate F1.csv F2.csv` (a joint fit) names the wild points of each flight; FIT.json lists
    them by flight."""
    from click.testing import CliRunner

    from rocketid.cli import main as cli
    _, glitched, times = logs
    a = glitched.to_csv(tmp_path / "glitched.csv")
    b = truth.measurements(Hidden(), seed=321).to_csv(tmp_path / "clean.csv")
    fit_json = tmp_path / "fit.json"
    res = CliRunner().invoke(cli, ["estimate", str(a), str(b), "--model", str(HERE / "vehicles" / "wren.py"), "--out",
                                   str(fit_json), *[x for n, s in STATED.items() for x in ("--sigma", f"{n}={s}")]])
    assert res.exit_code == 0, res.output
    assert "Warning: flight glitched: 3 sample(s) look like wild points" in res.output
    assert "flight clean:" not in res.output
    d = json.loads(fit_json.read_text())["wild_points"]
    assert sorted((p["channel"], p["t"]) for p in d["glitched"]) == sorted(times.items()) and d["clean"] == []
