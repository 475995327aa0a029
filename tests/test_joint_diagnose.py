"""``rocketid diagnose F1.csv F2.csv``: the diagnosis per flight and joint (issue 11, item 3).

Truth: two RA-66M flights simulated by the high-accuracy integrator with different noise seeds;
flight B's altimeter reads 5 m high (h + 5 m written into its measurements, not into a model),
flight A is clean. Each flight's diagnosis must find bias_h in B and nothing in A, the summary
must say "bias_h: found in flight B only", and the joint fit's consistency check must put the
misfit in B alone. About 30 s: one effect at most, no hold-out check.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cases.ra66 import ra66_times
from rocketid.cases.ra66m import ra66m, ra66m_truth
from rocketid.cli import main
from rocketid.commands.diagnose_flights import common_effects

FAST = ["--model", "ra66m", "--max-effects", "1", "--holdout", "none"]


@pytest.fixture(scope="module")
def flight_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flights")
    spec = ra66m()
    truth = ra66m_truth(spec)
    clean = ri.simulate_measurements(spec, truth, ra66_times(), seed=11)
    raw = ri.simulate_measurements(spec, truth, ra66_times(), seed=12)
    biased = ri.Measurements.from_arrays(raw["x"].times, {"x": raw["x"].values, "h": raw["h"].values + 5.0,
                                                          "v": raw["v"].values})
    return clean.to_csv(folder / "A.csv"), biased.to_csv(folder / "B.csv")


def test_an_effect_of_one_flight_is_reported_as_found_in_that_flight_only(flight_files, tmp_path):
    f1, f2 = flight_files
    out = tmp_path / "diag"
    res = CliRunner().invoke(main, ["diagnose", str(f1), str(f2), *FAST, "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "bias_h: found in flight B only" in res.output
    assert "no effect found in flight A" in res.output
    d = json.loads((out / "diagnosis.json").read_text())
    assert set(d["flights"]) == {"A", "B"}
    assert d["flights"]["B"]["final_effects"] == ["bias_h"] and d["flights"]["B"]["verdict"] == "explained"
    assert d["flights"]["A"]["final_effects"] == [] and d["flights"]["A"]["verdict"] == "nothing missing"
    assert d["flights"]["B"]["chi2_per_dof"] < 1.05 < d["flights"]["B"]["base_chi2_per_dof"]
    assert d["common"]["in_one_flight_only"] == {"bias_h": "B"} and d["common"]["in_every_flight"] == []
    # the joint fit of the base model, each flight refitted alone: the misfit is B's own
    joint = d["joint"]
    assert joint["success"] and joint["chi2_per_dof"] > 1.5
    assert joint["consistency"]["A"]["chi2_per_dof_alone"] < 1.1 < joint["consistency"]["B"]["chi2_per_dof_alone"]
    assert any("flight(s) B do not fit" in n for n in joint["notes"])
    # each flight's own report, and an index linking them
    for label in ("A", "B"):
        own = json.loads((out / label / "diagnosis.json").read_text())
        assert own["data"] == str(f1 if label == "A" else f2)
        assert (out / label / "report.html").is_file()
    index = (out / "index.html").read_text()
    assert 'href="A/report.html"' in index and 'href="B/report.html"' in index
    assert (out / "summary.txt").read_text().startswith("rocketid diagnosis of 2 flights")
    assert not list(out.glob(".*.tmp"))


def test_the_joint_fit_holds_the_noise_each_flight_took_from_its_data(flight_files, tmp_path):
    """``--sigma estimate`` on several flights: each flight's diagnosis takes its noise levels from
    its data alone (the scatter of fourth differences), and the joint fit holds the same values
    rather than estimating them from the base model's residuals, which hold B's altimeter bias.
    Truth: the flights were simulated with the model's noise levels, and A is clean."""
    f1, f2 = flight_files
    out = tmp_path / "diag"
    res = CliRunner().invoke(main, ["diagnose", str(f1), str(f2), *FAST, "--sigma", "estimate", "--out", str(out)])
    assert res.exit_code == 0, res.output
    d = json.loads((out / "diagnosis.json").read_text())
    joint = d["joint"]
    true_sigma = 1.0                                                       # ra66m's, in simulate_measurements
    for label, f in (("A", f1), ("B", f2)):
        own = json.loads((out / label / "diagnosis.json").read_text())["noise_from_data"]
        assert set(own) == {"x", "h", "v"}
        for ch, entry in own.items():
            assert joint["noise_from_data"][label][ch] == pytest.approx(entry["sigma"], rel=1e-12)
            assert joint["sigma"][label][ch] == pytest.approx(entry["sigma"], rel=1e-12)
            assert entry["sigma"] == pytest.approx(true_sigma, rel=0.05)     # 19 800 samples
    assert joint["success"]                     # the sigmas above are held, not relaxed to the residuals
    # judged against the sensors' noise, the clean flight fits and the biased one does not
    assert joint["consistency"]["A"]["chi2_per_dof_alone"] < 1.1 < joint["consistency"]["B"]["chi2_per_dof_alone"]
    assert any("from the data alone" in n for n in joint["notes"])
    assert d["flights"]["B"]["final_effects"] == ["bias_h"]


def test_a_file_that_cannot_be_read_among_several_is_named(flight_files, tmp_path):
    f1, f2 = flight_files
    bad = tmp_path / "broken.csv"
    bad.write_bytes(b"\x00\x01\xff\xfe binary")
    out = tmp_path / "diag"
    res = CliRunner().invoke(main, ["diagnose", str(f1), str(bad), str(f2), *FAST, "--out", str(out)])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and "broken.csv" in lines[0]
    assert not (out / "A").exists()                      # refused before any diagnosis
    missing = CliRunner().invoke(main, ["diagnose", str(f1), str(tmp_path / "nope.csv"), *FAST, "--out", str(out)])
    assert missing.exit_code == 2 and "nope.csv" in missing.output and len(missing.output.strip().splitlines()) == 1


def test_common_effects_names_every_flight_some_and_one_only():
    c = common_effects({"A": ("wind", "bias_h"), "B": ("wind",), "C": ("wind", "bias_h"), "D": ("wind", "thrust")})
    assert c["in_every_flight"] == ["wind"]
    assert c["in_one_flight_only"] == {"thrust": "D"} and c["in_some_flights"] == {"bias_h": ["A", "C"]}
    assert "thrust: found in flight D only" in c["statements"]
    assert "bias_h: found in flights A, C (not in B, D)" in c["statements"]
    assert common_effects({"A": (), "B": ()})["statements"] == ["no effect found in any flight"]
    none = common_effects({"A": None, "B": ()})
    assert none["not_searched"] == ["A"] and none["in_one_flight_only"] == {}


def test_the_per_flight_options_reach_each_flights_diagnosis(flight_files, tmp_path, monkeypatch):
    """--column, --sigma-column, --sigma, --window, --holdout, --max-effects, --workers and --refit-timeout
    are given to every flight's diagnose() (recorded here instead of diagnosing)."""
    from dataclasses import dataclass

    import numpy as np

    import rocketid.diagnostics as diagnostics
    from rocketid.errors import SettingsError

    files = []
    for path in flight_files:
        data = ri.read_csv(path, ["x", "h", "v"])
        t = data["x"].times
        new = tmp_path / path.name
        rows = np.column_stack([t, data["x"].values, data["h"].values, data["v"].values, np.full(t.size, 0.5)])
        new.write_text("t,x,alt,v,sv\n" + "\n".join(",".join(f"{v:.10g}" for v in r) for r in rows) + "\n")
        files.append(new)
    calls = []

    @dataclass(frozen=True)
    class Recorded:
        model: str = ""
        data_label: str = ""
        final: None = None

        def write(self, out):
            return None

    def record(data, spec, **kw):
        calls.append((data, kw))
        if len(calls) == 2:
            raise SettingsError("recorded")
        return Recorded()

    monkeypatch.setattr(diagnostics, "diagnose", record)
    res = CliRunner().invoke(main, ["diagnose", *map(str, files), "--model", "ra66m", "--out", str(tmp_path / "d"),
                                    "--column", "h=alt", "--sigma-column", "v=sv", "--sigma", "x=2",
                                    "--window", "5:60", "--holdout", "none", "--max-effects", "1", "--workers", "1",
                                    "--refit-timeout", "50", "--level", "0.01"])
    assert res.exit_code == 2 and "recorded" in res.output, res.output
    assert len(calls) == 2
    for data, kw in calls:
        assert kw["flight_window"] == (5.0, 60.0) and kw["holdout"] is None and kw["max_effects"] == 1
        assert kw["workers"] == 1 and kw["refit_timeout"] == 50.0 and kw["level"] == 0.01
        assert kw["sigma"] == {"x": 2.0}
        assert data["x"].sigma == 2.0 and np.all(data["v"].sigma == 0.5)   # given and per-sample sigmas read
    assert calls[0][0]["h"].values[0] != calls[1][0]["h"].values[0]        # each flight its own file's altitude
