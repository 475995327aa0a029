"""``rocketid diagnose`` on campaigns of three flights of one vehicle whose noise nobody states.

Each campaign (``tests/fleet_study/cases.py``) is three Petrel-V flights (``tests/vehicles/petrel.py``) flown by
the high-site study's independent truth (``tests/petrel_study/truth.py``): each flight with its own noise seed and
level (Petrel's GNSS x1, x1.5, x0.7) and possibly an effect of its own, the campaign possibly with one property of
the vehicle hidden in every flight. The CSVs state no sigma; the diagnosis runs with ``--sigma estimate``.

The normal suite checks the instruments (seconds): the CSVs hold no sigma and each flight's scatter is the level
stated, the shared property changes every flight by a stated amount, the flights of a campaign differ, and the
scoring rules. The diagnoses (one ``rocketid diagnose A.csv B.csv C.csv`` per campaign, minutes each) are
``slow``: ``pytest -m slow tests/test_fleet_study.py``; the whole study with its table is
``python3 tests/fleet_study/run.py --json fleet.json``.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest


import petrel as V

import rocketid as ri
from fleet_study.cases import BY_NAME, CAMPAIGNS, CHANNELS, Hidden, exact, noisy, write_campaign
from fleet_study.run import diagnose_campaign, row, score

#: Campaigns measured not to meet the bar (``score(...)["acceptable"]``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "nozzle+C-wind": "bb613fe (after the wind's limit of 120 m/s, 197672f/6cca436): flight C's path through "
                     "start_mass + wind_pl_5 + back_pressure_fade at chi2/dof 1.055 is refused for the 5-knot wind's "
                     "top knot at 124.8 m/s (beyond 120, for a 20 m/s jet), and C ends wind_pl_5 + thrust_profile_3 "
                     "at 1.056, partly explained (was wind_pl_9 + back_pressure_fade, 0.936, explained); the joint "
                     "model shares back_pressure_fade (A_e 0.0597 for 0.06) at 1.015. Not yet mended",
}
# (nozzle+C-wind before 2651fbd: flight C kept a start-mass error beside a 5-knot wind, partly explained; the finer
# shape mends it -- test_a_coarse_wind_chosen_before_the_nozzle_is_refined_with_it_in)


def _fourth_difference_sigma(y: np.ndarray) -> float:
    """The noise level of a steadily sampled channel from its fourth differences, sqrt(mean(d4^2) / 70)
    (docs/cli.md, "Noise levels estimated"), written here apart from rocketid's."""
    d4 = np.diff(y, 4)
    return float(math.sqrt(np.mean(d4 ** 2) / math.comb(8, 4)))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Every campaign's CSVs, written once."""
    root = tmp_path_factory.mktemp("fleet")
    return {c.name: write_campaign(c, root / c.name) for c in CAMPAIGNS}


def test_the_csvs_state_no_sigma(written):
    """A user's telemetry: the header is t, x, h, v and nothing else; rocketid reads each channel without a sigma
    (the diagnosis must estimate it, ``--sigma estimate``)."""
    for name, paths in written.items():
        assert [p.name for p in paths] == ["A.csv", "B.csv", "C.csv"], name
        for path in paths:
            with open(path, newline="") as fh:
                rows = list(csv.reader(fh))
            assert rows[0] == ["t", "x", "h", "v"], (name, path.name, rows[0])
            assert len(rows) == 601 and all(len(r) == 4 for r in rows[1:])
            assert not any("sigma" in cell.lower() for cell in rows[0])
            data = ri.read_csv(path)
            assert all(ch.sigma is None for ch in data.channels), (name, path.name)
            assert all(np.allclose(data[ch].times, V.sample_times()) for ch in CHANNELS)


@pytest.mark.parametrize("campaign", CAMPAIGNS, ids=[c.name for c in CAMPAIGNS])
def test_each_flight_s_scatter_is_the_stated_level(written, campaign):
    """The noise in the file (file minus the truth's exact outputs) is each flight's stated level, Petrel's GNSS
    (3 m, 4 m, 0.15 m/s) times 1, 1.5, 0.7 for A, B, C, within 10 % (600 samples: 2.9 % one-sigma; measured
    0.93-1.07); the fourth differences of the file alone -- what ``--sigma estimate`` can find -- see it within
    20 % (their one-sigma is 4.7 %: the differences overlap; measured 0.86-1.12, the lowest adapter-mass A's h,
    3.44 m for 4); so the three flights' noise really differs, B/A 1.5 and C/A 0.7 within 15 %."""
    for day, path in zip(campaign.days, written[campaign.name]):
        data = ri.read_csv(path)
        truth_out = exact(campaign.hidden(day))
        for ch in data.channels:
            stated = day.sigma[ch.name]
            scatter = float(np.std(ch.values - truth_out[ch.name]))
            assert abs(scatter / stated - 1) < 0.10, (day.label, ch.name, scatter, stated)
            assert abs(_fourth_difference_sigma(ch.values) / stated - 1) < 0.20, (day.label, ch.name)
    scatter = {d.label: {ch: float(np.std(noisy(campaign, d)[ch] - exact(campaign.hidden(d))[ch])) for ch in CHANNELS}
               for d in campaign.days}
    for ch in CHANNELS:
        assert scatter["B"][ch] / scatter["A"][ch] == pytest.approx(1.5, rel=0.15), ch
        assert scatter["C"][ch] / scatter["A"][ch] == pytest.approx(0.7, rel=0.15), ch


SHARED = [c for c in CAMPAIGNS if c.shared]


@pytest.mark.parametrize("campaign", SHARED, ids=[c.name for c in SHARED])
def test_the_shared_property_changes_every_flight(campaign):
    """The vehicle property hidden in the campaign moves every flight's outputs by the stated amount (its largest
    change against the same flight without it, measured: nozzle v 113 m/s, misalignment x 42 m, adapter v 33 m/s,
    blowdown v 66 m/s), and by more than 5 of that flight's own noise sigmas."""
    (channel, low, high), = campaign.shared_change
    for day in campaign.days:
        without = exact(Hidden(**dict(day.own)))
        moved = exact(campaign.hidden(day))
        change = float(np.max(np.abs(moved[channel] - without[channel])))
        assert low < change < high, (day.label, change)
        assert change > 5 * day.sigma[channel], (day.label, change, day.sigma[channel])


def test_each_flight_s_own_effect_moves_that_flight_only():
    """A flight's own effect (a height offset, a jet wind) is in that flight's truth and in no other's."""
    for campaign in CAMPAIGNS:
        for day in campaign.days:
            own = dict(day.own)
            for other in campaign.days:
                if other is not day:
                    for key in own:
                        assert getattr(campaign.hidden(other), key) != own[key], (campaign.name, day.label, key)
    b = BY_NAME["own-days"].day("B")
    moved = exact(BY_NAME["own-days"].hidden(b))["h"] - exact(Hidden())["h"]
    assert np.allclose(moved, 25.0, atol=1e-9)
    c = BY_NAME["own-days"].day("C")
    assert float(np.max(np.abs(exact(BY_NAME["own-days"].hidden(c))["x"] - exact(Hidden())["x"]))) > 100 * c.sigma["x"]


@pytest.mark.parametrize("campaign", CAMPAIGNS, ids=[c.name for c in CAMPAIGNS])
def test_the_flights_of_a_campaign_differ(written, campaign):
    """Three different days: three seeds (no seed used twice in the study), three noise levels, and noise
    realizations that are uncorrelated (|r| < 0.15 between any two flights' noise on any channel)."""
    assert len({d.seed for d in campaign.days}) == 3
    assert len({d.noise for d in campaign.days}) == 3
    noise = {d.label: {ch: ri.read_csv(p)[ch].values - exact(campaign.hidden(d))[ch] for ch in CHANNELS}
             for d, p in zip(campaign.days, written[campaign.name])}
    labels = [d.label for d in campaign.days]
    for i, a in enumerate(labels):
        for b in labels[i + 1:]:
            for ch in CHANNELS:
                r = np.corrcoef(noise[a][ch], noise[b][ch])[0, 1]
                assert abs(r) < 0.15, (campaign.name, a, b, ch, r)


def test_no_seed_is_used_twice():
    seeds = [d.seed for c in CAMPAIGNS for d in c.days]
    assert len(seeds) == len(set(seeds))
    assert not set(seeds) & set(range(500, 531)), "the Petrel study's seeds"


def _record(campaign, finals: dict, joint_final=None, exit_code=0):
    flights = {label: {"final_effects": list(eff), "verdict": verdict, "chi2_per_dof": 1.0, "base_chi2_per_dof": 5.0}
               for label, (eff, verdict) in finals.items()}
    return {"exit": exit_code, "wall_s": 1.0, "diagnosis": {"flights": flights, "joint_final": joint_final},
            "flight_detail": {}}


def test_scoring_rules():
    """The worst outcome is a wrong family called explained; a clean flight that adds anything fails; a vehicle
    property must be shared with one value close to the truth; the adapter's mass is per flight."""
    clean = BY_NAME["clean"]
    assert score(clean, _record(clean, {l: ((), "nothing missing") for l in "ABC"}))["acceptable"]
    bad = score(clean, _record(clean, {"A": ((), "nothing missing"), "B": (("bias_h",), "explained"),
                                       "C": ((), "nothing missing")}))
    assert bad["outcome"] == "WRONG called explained" and not bad["acceptable"]

    nozzle = BY_NAME["nozzle"]
    finals = {l: (("back_pressure",), "explained") for l in "ABC"}
    jf = {"effects": {l: ["back_pressure"] for l in "ABC"}, "shared": ["back_pressure"], "fits_to_noise": True,
          "parameters": {"A_e": {"value": 0.0603, "std": 0.0002}}}
    assert score(nozzle, _record(nozzle, finals, jf))["outcome"] == "right & explained"
    off = {**jf, "parameters": {"A_e": {"value": 0.07, "std": 0.0002}}}
    assert not score(nozzle, _record(nozzle, finals, off))["acceptable"]
    apart = {**jf, "shared": [], "parameters": {f"A_e[{l}]": {"value": 0.06, "std": 0.001} for l in "ABC"}}
    assert not score(nozzle, _record(nozzle, finals, apart))["acceptable"]
    carried = {**jf}                                           # C found nothing, the joint step carried it there
    s = score(nozzle, _record(nozzle, {**finals, "C": ((), "nothing missing")}, carried))
    assert s["acceptable"], s
    wrong = score(nozzle, _record(nozzle, {**finals, "B": (("thrust_profile_3",), "explained")}, jf))
    assert wrong["outcome"] == "WRONG called explained"

    mass = BY_NAME["adapter-mass"]
    finals = {l: (("start_mass",), "explained") for l in "ABC"}
    per = {"effects": {l: ["start_mass"] for l in "ABC"}, "shared": [], "fits_to_noise": True,
           "parameters": {f"dm_start[{l}]": {"value": 40.5, "std": 0.5} for l in "ABC"}}
    assert score(mass, _record(mass, finals, per))["acceptable"]
    one = {**per, "shared": ["start_mass"], "parameters": {"dm_start": {"value": 40.5, "std": 0.3}}}
    assert not score(mass, _record(mass, finals, one))["acceptable"]

    own = BY_NAME["own-days"]
    finals = {"A": ((), "nothing missing"), "B": (("bias_h",), "explained"), "C": (("wind_pl_9",), "explained")}
    jf = {"effects": {"A": [], "B": ["bias_h"], "C": ["wind_pl_9"]}, "shared": [], "fits_to_noise": True,
          "parameters": {"b_h[B]": {"value": 25.1, "std": 0.3}}}
    assert score(own, _record(own, finals, jf))["acceptable"]
    into_a = {**jf, "effects": {**jf["effects"], "A": ["wind_pl_9"]}}
    assert not score(own, _record(own, finals, into_a))["acceptable"]
    assert "| own-days |" in row(own, _record(own, finals, jf))


def test_a_coarse_wind_chosen_before_the_nozzle_is_refined_with_it_in(tmp_path):
    """Flight C of campaign nozzle+C-wind: a nozzle term (0.06 m^2 on a sea-level thrust table) and a jet stream
    (3 -> 6 m/s, 20 m/s at 12 km), noise stated nowhere. Its search took a start-mass error at step 1 (-107 kg,
    carrying the nozzle's thrust), a 5-knot wind at step 2 and the nozzle's fade at step 3: chi2/dof 1.055 inside
    the band, x residuals not white, the start mass kept at 3.4 kg -- the wind's knot count had been chosen with
    the nozzle still missing. The finer shape (step module note 8) refits the wind one and two rungs up with the
    others in, each also without each other effect: the 9-knot wind with the nozzle alone explains the data, the
    start mass left out, the exit area within 2 % of the truth and the jet's peak within 15 %."""
    from rocketid.diagnostics import step as S
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.effects import CATALOGUE
    from study_harness import SetCheck

    campaign = BY_NAME["nozzle+C-wind"]
    data = ri.read_csv(write_campaign(campaign, tmp_path)[2])
    base, _, counts, _, _ = base_fit(V.build_model(), data, "estimate")
    check = SetCheck(base, noise_band(base, estimated=counts))
    ctx, shapes = check.ctx, check.shapes("wind", "back_pressure")
    found = [shapes["start_mass"], shapes["wind_pl_5"], shapes["back_pressure_fade"]]
    last = check.judge(found)
    assert not last.accepted, [c.name for c in last.checks if not c.passed]
    candidates = [CATALOGUE[n] for n in ("start_mass", "wind", "back_pressure")]
    effects, acc, why = S._finer(found, last, base, candidates, ctx)
    assert "wind_pl_9 in place of wind_pl_5" in why and acc.accepted, why
    if "start_mass" in [e.name for e in effects]:
        # from the base fit the set without the start mass may stop at another optimum (chi2/dof 1.064, x not
        # white, with this machine's packages on 2026-11-28; 0.936 the day before): the backward check from the
        # found set's own fit finds it
        fit = S._fit_of(ctx.base_spec, effects, acc.refit, base.prepared.measurements,
                        base.prepared.transcription.mesh, None)
        effects, acc, why = S._without_one(ctx, base, fit, effects, acc)
    assert [e.name for e in effects] == ["wind_pl_9", "back_pressure_fade"], why
    assert acc.accepted and "without start_mass" in why, why
    r = acc.refit
    assert abs(r.estimate("A_e")[0] - 0.06) < 0.0012
    peak = max(r.estimate(f"W_{j}")[0] for j in range(9))
    assert abs(peak - 26.0) < 0.15 * 26.0, peak


@pytest.mark.slow
@pytest.mark.parametrize("campaign", CAMPAIGNS, ids=[c.name for c in CAMPAIGNS])
def test_diagnose_on_fleet_campaign(campaign, tmp_path, request):
    """``rocketid diagnose A.csv B.csv C.csv --sigma estimate`` (CLI) on the campaign: it runs, no wrong family is
    called explained in any flight, a clean flight adds nothing (nor gets anything carried into it), and the
    campaign meets the bar (``score``: each flight's own effects found, the vehicle's property in every flight and
    shared with one value close to the truth, the adapter's mass per flight, the joint model at the noise)."""
    if campaign.name in KNOWN_FAILURES:
        request.node.add_marker(pytest.mark.xfail(reason=KNOWN_FAILURES[campaign.name], strict=False))
    record = diagnose_campaign(campaign, root=tmp_path)
    assert record["exit"] in (0, 1), record["stderr"]
    s = score(campaign, record)
    assert not s["wrong_explained"], row(campaign, record)
    flights = record["diagnosis"]["flights"]
    joint = (record["diagnosis"].get("joint_final") or {}).get("effects") or {}
    for day in campaign.days:
        if not campaign.right(day):
            assert not flights[day.label]["final_effects"] and not joint.get(day.label), row(campaign, record)
    assert s["acceptable"], row(campaign, record)
