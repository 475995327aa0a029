"""Several flights: the joint model with the effects each flight's diagnosis found.

Truth: the hidden-effect study's own truth model of RA-66 (``tests/discovery_study/truth.py``:
a vector force balance, the thrust scaled by ``1 + eps`` in its own expression, the altimeter's
bias added to the simulated readings), not the catalogue's expressions. Three flights:

- A: thrust 2 % above the stated one;
- B: the same engine (thrust +2 %) and an altimeter reading 5 m high;
- C: another engine, thrust 3.5 % above the stated one.

A and B share the thrust error (one value: 0.02), B's bias is its own; A and C differ (0.02 and
0.035), so the thrust error is not one property of the vehicle and stays per flight. About 45 s:
at most two effects per flight, no hold-out check.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from discovery_study.truth import measure, ra66_vehicle
from rocketid.cli import main
from rocketid.diagnostics import CATALOGUE
from rocketid.diagnostics.effects import Vehicle, throttle_effect
from rocketid.diagnostics.flights import effect_nature, sharing_plan

FAST = ["--model", "ra66", "--max-effects", "2", "--holdout", "none"]
TRUTH = {"A": {"thrust_level": {"eps_thrust": 0.02}},
         "B": {"thrust_level": {"eps_thrust": 0.02}, "bias_h": {"b_h": 5.0}},
         "C": {"thrust_level": {"eps_thrust": 0.035}}}


@pytest.fixture(scope="module")
def flight_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flights")
    vehicle = ra66_vehicle()
    return {label: measure(vehicle, effects, seed=400 + i).to_csv(folder / f"{label}.csv")
            for i, (label, effects) in enumerate(TRUTH.items())}


def _diagnose(files, labels, out, *options):
    res = CliRunner().invoke(main, ["diagnose", *[str(files[l]) for l in labels], *FAST, *options, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return res, json.loads((out / "diagnosis.json").read_text())


def test_an_effect_the_flights_agree_on_is_fitted_once_and_a_flights_own_stays_its_own(flight_files, tmp_path):
    res, d = _diagnose(flight_files, ["A", "B"], tmp_path / "diag")
    final = d["joint_final"]
    assert final["effects"] == {"A": ["thrust_level"], "B": ["thrust_level", "bias_h"]}
    assert final["nature"] == {"thrust_level": "vehicle", "bias_h": "flight"}
    (test,) = final["tests"]
    assert test["effect"] == "thrust_level" and test["flights"] == ["A", "B"] and test["dof"] == 1
    assert test["shared"] and test["p_value"] >= 0.05
    assert final["shared"] == ["thrust_level"]
    params = final["parameters"]
    assert set(params) == {"eps_thrust", "b_h[B]"}                      # one thrust error, B's bias its own
    eps, b_h = params["eps_thrust"], params["b_h[B]"]
    assert abs(eps["value"] - 0.02) < 4 * eps["std"] and eps["std"] < 1e-4
    assert abs(b_h["value"] - 5.0) < 4 * b_h["std"]
    # the error falls to the noise in the joint model, flight by flight
    assert final["success"] and final["fits_to_noise"]
    assert final["chi2_per_dof"] < 1.05 < 10 < final["base_chi2_per_dof"]
    assert all(row["fits_to_noise"] for row in final["per_flight"].values())
    assert "Joint model with the effects found" in res.output
    assert "thrust_level: one value for flights A, B" in res.output
    assert any(v.startswith("Every flight reaches its noise in the joint model") for v in d["verdict"])
    # each flight's refits were kept while the command ran, and removed when it ended
    assert (tmp_path / "diag" / "A" / "report.html").is_file() and not list((tmp_path / "diag").glob("*/checkpoints"))


def test_an_effect_that_differs_between_flights_is_kept_per_flight(flight_files, tmp_path):
    # the lift coefficient each flight's own (--per-flight, as an attitude program would be): the joint fits keep it
    res, d = _diagnose(flight_files, ["A", "C"], tmp_path / "diag", "--per-flight", "C*L")
    final = d["joint_final"]
    (test,) = final["tests"]
    assert test["effect"] == "thrust_level" and not test["shared"] and test["p_value"] < 1e-6
    own = test["own"]
    assert abs(own["A"]["eps_thrust"]["value"] - 0.02) < 1e-3 and abs(own["C"]["eps_thrust"]["value"] - 0.035) < 1e-3
    assert final["shared"] == []
    assert set(final["parameters"]) == {"eps_thrust[A]", "eps_thrust[C]"}
    assert final["fits_to_noise"]
    assert {"CL[A]", "CL[C]"} <= set(d["joint"]["parameters"]) and "CL" not in d["joint"]["parameters"]
    assert "thrust_level: differs between flights A, C" in res.output
    assert "not one property of the vehicle" in res.output
    # in engineering terms beside the test's: 0.015 apart, three quarters of a realistic thrust error (2 %)
    width, share = test["spread"]["eps_thrust"]["width"], test["spread"]["eps_thrust"]["of_realistic_size"]
    assert abs(width - 0.015) < 1e-3 and abs(share - 0.75) < 0.06
    assert "eps_thrust 0.015 apart (75 % of its realistic size)" in res.output
    assert "small in engineering terms" not in res.output


def test_a_spread_the_test_resolves_but_smaller_than_a_tenth_of_a_realistic_size_is_called_small():
    from rocketid.diagnostics.flights import SMALL_SPREAD, SharingTest
    own = {"A": {"eps_thrust": (0.0200, 2e-5)}, "B": {"eps_thrust": (0.0203, 2e-5)}}
    t = SharingTest("thrust_level", ("A", "B"), ("eps_thrust",), own, 250.0, 1, 1e-50, False,
                    sizes={"eps_thrust": 0.02})
    (width, share), = t.spread().values()
    assert width == pytest.approx(3e-4) and share == pytest.approx(0.015) and share < SMALL_SPREAD
    text = t.sentence()
    assert "differs between flights A, B" in text and "(1.5 % of its realistic size)" in text
    assert "differ by less than 10 % of a realistic size" in text and "small in engineering terms" in text
    # without a realistic size there is no yardstick, and no such words
    bare = SharingTest("thrust_level", ("A", "B"), ("eps_thrust",), own, 250.0, 1, 1e-50, False)
    assert "eps_thrust 0.0003 apart)" in bare.sentence() and "engineering" not in bare.sentence()


def test_the_nature_of_an_effect_follows_its_physics():
    for name in ("thrust_level", "back_pressure", "mass_flow", "transonic_drag", "base_drag", "misalignment"):
        assert effect_nature(CATALOGUE[name]) == "vehicle", name
    for name in ("bias_h", "scale_v", "time_offset", "wind", "density", "earth_rotation", "start_speed",
                 "start_mass"):
        assert effect_nature(CATALOGUE[name]) == "flight", name
    # the refined and located shapes: a throttle window, a jettison at a time, a user's throttle are the flight's;
    # a drag table in Mach and a thrust profile are the vehicle's
    vehicle = Vehicle(thrust=1e5, mass=1e4, mass_flow=100.0, speed=1000.0, start_speed=0.0, duration=60.0,
                      altitude=(0.0, 20e3), mach=(0.0, 3.0), sigma={"h": 1.0}, sample_interval=0.01,
                      knot_times=tuple(float(t) for t in range(0, 61, 6)), mach_knots=(0.0, 0.8, 1.2, 2.0, 3.0),
                      powered=(0.0, 60.0))
    shapes = {e.name: e for fam in ("thrust_level", "start_mass", "transonic_drag")
              for e in CATALOGUE[fam].refinements(vehicle)}
    assert effect_nature(shapes["throttle_window"]) == "flight"
    assert effect_nature(shapes["mass_jettison"]) == "flight"
    assert effect_nature(throttle_effect([10.0, 20.0, 30.0])) == "flight"
    assert any(n.startswith("thrust_profile") for n in shapes)
    for n, e in shapes.items():
        if n.startswith(("thrust_profile", "drag_mach")):
            assert effect_nature(e) == "vehicle", n


def test_a_parameter_two_effects_declare_is_never_shared():
    declared = {
        "A": [("thrust_level", "vehicle", ("eps_thrust",)), ("drag_mach_6", "vehicle", ("dCD_M0", "dCD_M1")),
              ("bias_h", "flight", ("b_h",))],
        "B": [("thrust_level", "vehicle", ("eps_thrust",)), ("drag_mach_8", "vehicle", ("dCD_M0", "dCD_M1")),
              ("bias_h", "flight", ("b_h",))],
        "C": [("mass_flow", "vehicle", ("eps_mdot",))],
    }
    shareable, own = sharing_plan(declared)
    assert shareable == {"thrust_level": (("A", "B"), ("eps_thrust",))}
    # two drag tables on other knots name the same parameters: each flight keeps its own; a sensor's bias found
    # in two flights is each flight's; a vehicle effect of one flight has nothing to share with
    assert own == {"dCD_M0", "dCD_M1", "b_h", "eps_mdot"}


def test_per_flight_parameters_are_checked_before_any_work(flight_files, tmp_path):
    one = CliRunner().invoke(main, ["diagnose", str(flight_files["A"]), *FAST, "--per-flight", "CL",
                                    "--out", str(tmp_path / "one")])
    assert one.exit_code == 2 and "--per-flight needs several data files" in one.output
    bad = CliRunner().invoke(main, ["diagnose", str(flight_files["A"]), str(flight_files["B"]), *FAST,
                                    "--per-flight", "alpha*", "--out", str(tmp_path / "bad")])
    assert bad.exit_code == 2 and "--per-flight alpha*: no parameter of RA-66 matches" in bad.output
    assert "CD0" in bad.output and not (tmp_path / "bad" / "A").exists()


# ---- a vehicle effect found in some flights, carried to the others ----------------------------------------------

def _as_diagnosed(label, data, effects):
    """A flight as a diagnosis that ended with ``effects`` leaves it: its base fit, the fit of its final model and
    its noise band (real fits; the search itself is not run: its choice between rivals is what is given)."""
    from types import SimpleNamespace

    from rocketid import estimate
    from rocketid.cases.ra66 import ra66
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.effects import with_effects
    from rocketid.joint import Flight

    base = estimate(ra66(), data)
    fit = estimate(with_effects(base.spec, list(effects)), data, mesh=base.prepared.transcription.mesh) \
        if effects else base
    assert base.success and fit.success
    disc = SimpleNamespace(effects=tuple(effects), base_fit=base, fit=fit, band=noise_band(fit))
    return Flight(label, base.spec, data, base.prepared.transcription.mesh), SimpleNamespace(discovery=disc), base


def _joint(cases):
    from rocketid.diagnostics.flights import joint_final
    from rocketid.joint import joint_estimate

    flights, reports = zip(*[(f, r) for f, r, _ in cases])
    base = joint_estimate(list(flights))
    return joint_final(list(flights), list(reports), base.chi2_per_dof)


@pytest.fixture(scope="module")
def thrust_flights():
    vehicle = ra66_vehicle()
    return {label: measure(vehicle, effects, seed=410 + i) for i, (label, effects) in enumerate(
        {"A": {"thrust_level": {"eps_thrust": 0.02}}, "B": {"thrust_level": {"eps_thrust": 0.02}},
         "C": {"thrust_level": {"eps_thrust": 0.035}}, "D": {}}.items())}


def test_a_vehicle_effect_one_flight_found_is_carried_to_a_flight_whose_search_took_a_rival(thrust_flights):
    """A and B fly the same engine, 2 % above its stated thrust. A's search found the thrust error; B's took a
    start-mass error for it (as a search may, where the two fit a flight alike). The thrust error is the
    vehicle's: tried in B with one value for both, the flights agree, and B's start-mass error no longer lowers
    the joint BIC and is dropped -- one thrust error, both flights at their noise."""
    thrust, start_mass = CATALOGUE["thrust_level"], CATALOGUE["start_mass"]
    final = _joint([_as_diagnosed("A", thrust_flights["A"], [thrust]),
                    _as_diagnosed("B", thrust_flights["B"], [start_mass])])
    (c,) = final.carried
    assert c.effect == "thrust_level" and c.found_in == ("A",) and c.to == ("B",)
    assert c.carried and c.p_value >= 0.05 and c.dof == 1 and c.fall > 0
    assert c.dropped == {"B": ("start_mass",)}
    assert final.effects == {"A": ("thrust_level",), "B": ("thrust_level",)}
    assert final.shared == ("thrust_level",)
    values = {n: (v, s) for n, v, s in final._values()}
    assert set(values) == {"eps_thrust"}
    eps, std = values["eps_thrust"]
    assert abs(eps - 0.02) < 4 * std and std < 1e-4
    assert final.fits_to_noise
    assert "carried to every flight" in " ".join(final.sentences())
    assert "B drops start_mass" in " ".join(final.sentences())
    d = final.to_dict()
    assert d["carried"][0]["carried"] and d["carried"][0]["dropped"] == {"B": ["start_mass"]}


def test_a_vehicle_effect_is_not_carried_to_flights_that_disagree_on_its_value(thrust_flights):
    """C's engine is 3.5 % above the stated thrust and its search found a start-mass error; D's data are clean
    and its search found nothing. A's 2 % is no value for C nor for D: neither takes it, each keeps its model."""
    thrust, start_mass = CATALOGUE["thrust_level"], CATALOGUE["start_mass"]
    a = _as_diagnosed("A", thrust_flights["A"], [thrust])
    for other, effects in (("C", [start_mass]), ("D", [])):
        final = _joint([a, _as_diagnosed(other, thrust_flights[other], effects)])
        (c,) = final.carried
        assert c.effect == "thrust_level" and c.to == (other,)
        assert not c.carried and c.p_value < 1e-6, other
        assert final.effects == {"A": ("thrust_level",), other: tuple(e.name for e in effects)}
        assert final.shared == ()
        assert "do not agree on one value" in " ".join(final.sentences())


def test_a_flights_own_effect_found_in_two_flights_is_tried_in_each_of_the_others():
    """A, B and C carry the same altimeter, reading 5 m high; D's reads true. A's and B's searches found the bias;
    C's is given as having stopped without it (as a search may, between rivals at the noise). The bias is each
    flight's own (a sensor): never one value for the campaign, but found in two flights it is tried in each of
    the others with a value of its own -- added to C (5 m), not to D (nothing to take up). Without this, C's
    misfit stayed in the joint model and the shared coefficients took it up (measured on three Petrel-V flights
    with a 40 kg adapter nobody declared: the third flight's search tied and added nothing, and the joint model
    put the other two flights' start masses at 0.08 kg for 40)."""
    vehicle = ra66_vehicle()
    bias = {"bias_h": {"b_h": 5.0}}
    data = {label: measure(vehicle, fx, seed=420 + i)
            for i, (label, fx) in enumerate({"A": bias, "B": bias, "C": bias, "D": {}}.items())}
    b_h = CATALOGUE["bias_h"]
    final = _joint([_as_diagnosed("A", data["A"], [b_h]), _as_diagnosed("B", data["B"], [b_h]),
                    _as_diagnosed("C", data["C"], []), _as_diagnosed("D", data["D"], [])])
    tried = {c.to: c for c in final.carried if c.own}
    assert set(tried) == {("C",), ("D",)}
    assert all(c.effect == "bias_h" and c.found_in == ("A", "B") and c.dof == 1 for c in tried.values())
    assert tried[("C",)].carried and tried[("C",)].p_value < 1e-10
    assert not tried[("D",)].carried
    assert final.effects == {"A": ("bias_h",), "B": ("bias_h",), "C": ("bias_h",), "D": ()}
    assert final.shared == ()
    assert final.fits_to_noise
    text = " ".join(final.sentences())
    assert "bias_h (found in A, B, tried in C with a value of its own): added there" in text
    assert "tried in D with a value of its own): not added" in text
    assert final.to_dict()["carried"][0]["own"]
