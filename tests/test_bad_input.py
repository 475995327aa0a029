"""Bad input fails at the boundary with rocketid's own exception, naming the input.

Each test checks the exception *type* (``rocketid.errors``) and that the message names
the offending file, column, channel, symbol or option, and that the error was raised by
rocketid's validation, not deep inside NumPy, SciPy or SymPy (no chained exception).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.errors import DataError, ModelError, RocketidError, SettingsError

PACKAGE_DIR = Path(ri.__file__).resolve().parent
GOOD_ROWS = "0.1,1.0,2.0,3.0\n0.2,1.5,2.5,3.5\n0.3,2.0,3.0,4.0\n"


def _raises(exc_type, fn, *fragments):
    """Call ``fn``; it must raise ``exc_type`` whose message contains every fragment."""
    with pytest.raises(exc_type) as info:
        fn()
    err = info.value
    assert isinstance(err, RocketidError)
    message = str(err)
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in: {message}"
    # raised by rocketid's validation, not re-wrapped from a deep failure
    assert err.__cause__ is None
    raised_in = Path(str(info.traceback[-1].path)).resolve()
    assert PACKAGE_DIR in raised_in.parents, raised_in
    return message


def _csv(tmp_path, text, name="data.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------
# CSV files
# ---------------------------------------------------------------------------


def test_csv_round_trip_is_the_baseline(tmp_path, ra66_noisy):
    """The well-formed case reads back exactly (so the failures below are about the defects)."""
    path = ra66_noisy.to_csv(tmp_path / "ra66.csv")
    back = ri.read_csv(path)
    for name in ("x", "h", "v"):
        np.testing.assert_array_equal(back[name].values, ra66_noisy[name].values)
        np.testing.assert_array_equal(back[name].times, ra66_noisy[name].times)
    assert ri.read_csv(_csv(tmp_path, "t,x,h,v\n" + GOOD_ROWS))["v"].values[-1] == 4.0


@pytest.mark.parametrize("cell", ["nan", "NaN", "inf"])
def test_csv_with_nan(tmp_path, cell):
    path = _csv(tmp_path, f"t,x,h,v\n0.1,1,2,3\n0.2,1,{cell},3\n0.3,1,2,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "'h'", "t = 0.2")


def test_csv_empty_cell_is_not_measured(tmp_path):
    """An empty cell means "not measured at that time" (multi-rate telemetry): the channel
    has one sample fewer; an explicit NaN stays an error (above)."""
    data = ri.read_csv(_csv(tmp_path, "t,x,h,v\n0.1,1,2,3\n0.2,1,,3\n0.3,1,2,3\n"))
    np.testing.assert_array_equal(data["h"].times, [0.1, 0.3])
    np.testing.assert_array_equal(data["x"].times, [0.1, 0.2, 0.3])


def test_csv_empty_time_cell(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,2,3\n,1,2,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "line 3", "time cell ('t') is empty")


def test_csv_column_without_values(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,,3\n0.2,1,,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "column(s) h have no values")


def test_csv_with_nan_time(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,2,3\nnan,1,2,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "time", "sample 1")


def test_csv_with_unsorted_times(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,2,3\n0.3,1,2,3\n0.2,1,2,3\n")
    message = _raises(DataError, lambda: ri.read_csv(path), "not sorted", "0.3", "0.2")
    assert "sort" in message


def test_csv_with_duplicate_times(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,2,3\n0.2,1,2,3\n0.2,1,2,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "duplicate", "t = 0.2")


def test_csv_with_missing_columns(tmp_path):
    path = _csv(tmp_path, "t,x,alt\n0.1,1,2\n")
    _raises(DataError, lambda: ri.read_csv(path), "data.csv", "missing column(s) h, v", "t, x, alt")
    # mapped to a column that is not there either
    _raises(DataError, lambda: ri.read_csv(path, column_map={"h": "altitude", "v": "alt"}), "altitude")
    # a mapping to the right column works
    ok = ri.read_csv(path, channels=("x", "h"), column_map={"h": "alt"})
    assert ok["h"].values.tolist() == [2.0]


def test_csv_without_time_column(tmp_path):
    path = _csv(tmp_path, "time,x,h,v\n0.1,1,2,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "missing column(s) t")


def test_csv_with_non_numeric_cell(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n0.1,1,2,3\n0.2,1,2,3\n0.3,1,12 m/s,3\n")
    _raises(DataError, lambda: ri.read_csv(path), "data.csv", "line 4", "'h'", "'12 m/s'", "not a number")


def test_csv_empty_file(tmp_path):
    _raises(DataError, lambda: ri.read_csv(_csv(tmp_path, "")), "data.csv", "empty")


def test_csv_with_header_only(tmp_path):
    _raises(DataError, lambda: ri.read_csv(_csv(tmp_path, "t,x,h,v\n\n")), "data.csv", "no data rows")


def test_csv_missing_file(tmp_path):
    _raises(DataError, lambda: ri.read_csv(tmp_path / "nope.csv"), "nope.csv", "does not exist")


# ---------------------------------------------------------------------------
# noise standard deviations
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("sigma", [0.0, -1.0, math.inf, math.nan])
def test_non_positive_sigma_in_model_output(sigma):
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    message = _raises(ModelError, lambda: m.output("y_meas", y, sigma=sigma), "sigma of output y_meas")
    assert ("NaN" if math.isnan(sigma) else "positive") in message


def test_non_numeric_sigma_in_model_output():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    _raises(ModelError, lambda: m.output("y", y, sigma="one"), "sigma of output y", "'one'")


@pytest.mark.parametrize("sigma", [0.0, -0.5, math.nan])
def test_non_positive_sigma_in_read_csv(tmp_path, sigma):
    path = _csv(tmp_path, "t,x,h,v\n" + GOOD_ROWS)
    _raises(DataError, lambda: ri.read_csv(path, sigma={"v": sigma}), "'v'", "sigma", "positive")


def test_sigma_for_unknown_channel_in_read_csv(tmp_path):
    path = _csv(tmp_path, "t,x,h,v\n" + GOOD_ROWS)
    _raises(DataError, lambda: ri.read_csv(path, sigma={"vel": 1.0}), "'vel'", "x, h, v")
    _raises(DataError, lambda: ri.read_csv(path, sigma={"x": "1 m"}), "'x'", "'1 m'")


# ---------------------------------------------------------------------------
# parameter guesses and bounds
# ---------------------------------------------------------------------------


def test_parameter_guess_outside_bounds_in_the_model():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    with pytest.raises(ModelError, match=r"guess 5 of parameter k .*\[0, 1\]"):
        k = m.parameter("k", 5.0, bounds=(0.0, 1.0))
        m.ode({y: -k * y})
        m.output("y", y, sigma=1.0)
        m.freeze()


def test_parameter_bounds_reversed():
    m = ri.Model("m", 0.0, 1.0)
    _raises(ModelError, lambda: m.parameter("k", 0.5, bounds=(1.0, 0.0)), "parameter k", "lower bound")


def test_estimate_guess_outside_bounds(ra66_spec, ra66_noisy_prepared):
    data, pr = ra66_noisy_prepared.measurements, ra66_noisy_prepared
    _raises(ModelError, lambda: ri.estimate(ra66_spec, data, guess={"CD0": 2.0}, prepared=pr),
            "parameter CD0", "2", "bounds")
    _raises(ModelError, lambda: ri.estimate(ra66_spec, data, guess=[0.5] * 7 + [-0.1], prepared=pr),
            "parameter CL", "-0.1")


def test_estimate_guess_unknown_name(ra66_spec, ra66_noisy_prepared):
    pr = ra66_noisy_prepared
    _raises(ModelError, lambda: ri.estimate(ra66_spec, pr.measurements, guess={"CD7": 0.1}, prepared=pr),
            "'CD7'", "did you mean", "CD6")
    _raises(ModelError, lambda: ri.estimate(ra66_spec, pr.measurements, guess={"Cl": 0.1}, prepared=pr), "'Cl'")
    _raises(ModelError, lambda: ri.estimate(ra66_spec, pr.measurements, guess=[0.5] * 5, prepared=pr),
            "5 values", "8")


# ---------------------------------------------------------------------------
# solver settings and failures
# ---------------------------------------------------------------------------


def test_ipopt_failure_is_a_result_not_an_exception(ra66_spec, ra66_noisy_prepared):
    pr = ra66_noisy_prepared
    fit = ri.estimate(ra66_spec, pr.measurements, options={"max_iter": 1}, prepared=pr)
    assert fit.success is False
    assert fit.status == -1  # IPOPT: maximum number of iterations exceeded
    text = fit.summary().text()
    assert "FAILED" in text
    notes = text.split("\nNotes\n", 1)[1]
    assert "[1] IPOPT did not converge" in notes and "Maximum number of iterations" in notes
    assert fit.to_dict()["success"] is False


def test_unknown_ipopt_option_names_close_matches(ra66_spec, ra66_noisy_prepared):
    pr = ra66_noisy_prepared
    _raises(SettingsError, lambda: ri.estimate(ra66_spec, pr.measurements, options={"max_iters": 3}, prepared=pr),
            "'max_iters'", "did you mean", "max_iter")
    _raises(SettingsError, lambda: ri.estimate(ra66_spec, pr.measurements, options={"tol": "small"}, prepared=pr),
            "'tol'", "float", "'small'")


def test_family_breakpoint_not_on_an_element_boundary(ra66_spec, ra66_noisy):
    mesh = ri.uniform_mesh(0.0, 66.0, 20, 3)  # 3.3 s elements: 11 s is inside one
    _raises(SettingsError, lambda: ri.prepare(ra66_spec, ra66_noisy, mesh=mesh),
            "breakpoint t = 11", "family CD", "element boundary")


def test_mesh_not_spanning_the_horizon(ra66_spec, ra66_noisy):
    _raises(SettingsError, lambda: ri.prepare(ra66_spec, ra66_noisy, mesh=ri.uniform_mesh(0.0, 60.0, 60, 3)),
            "[0, 60]", "[0, 66]")


# ---------------------------------------------------------------------------
# model and data that do not fit together; undeclared symbols
# ---------------------------------------------------------------------------


def test_model_output_missing_from_the_data(ra66_spec, ra66_noisy):
    """Issue 11: an output the data lack is predicted, not fitted (it was an error); data with
    none of the model's outputs are still refused, naming both sides."""
    prepared = ri.prepare(ra66_spec, ra66_noisy.subset(["x", "h"]))
    assert prepared.nlp.channel_names == ("x", "h")
    other = ri.Measurements.from_arrays(ra66_noisy["x"].times, {"alt": ra66_noisy["h"].values})
    _raises(DataError, lambda: ri.prepare(ra66_spec, other), "none of model 'RA-66''s outputs (x, h, v)", "alt")


def test_data_outside_the_horizon():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    k = m.parameter("k", 1.0)
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.1)
    data = ri.Measurements.from_arrays([0.5, 1.5], {"y": [1.0, 0.5]})
    _raises(DataError, lambda: ri.prepare(m.freeze(), data), "'y'", "1.5", "[0, 1]")


def test_undeclared_symbol_in_an_equation():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    m.ode({y: -sp.Symbol("kdecay") * y})
    m.output("y", y, sigma=1.0)
    _raises(ModelError, m.freeze, "kdecay", "equation of y", "not declared")


def test_undeclared_symbol_in_an_output():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    m.ode({y: -y})
    m.output("y", sp.Symbol("gain") * y, sigma=1.0)
    _raises(ModelError, m.freeze, "gain", "output y")


def test_input_depending_on_another_symbol():
    m = ri.Model("m", 0.0, 1.0)
    _raises(ModelError, lambda: m.input("u", sp.Symbol("w") * m.t), "input u", "w")


def test_missing_equation():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    m.state("z", 0.0)
    m.ode({y: -y})
    m.output("y", y, sigma=1.0)
    _raises(ModelError, m.freeze, "no equation for state(s) z")


def test_implicit_equation_without_the_derivative():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    _raises(ModelError, lambda: m.implicit({y: y - 1}), "dy_dt", "m.der(y)")
