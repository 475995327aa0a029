"""Telemetry as it comes: multi-rate channels, drop-outs, per-channel files, flight windows,
unmeasured outputs, quantized and per-sample noise, units checks.

The truths are RA-66 simulations (SciPy DOP853 at tolerance 1e-12, not the collocation that
estimates) at CD = 0.5, CL = 0.1, sampled the way telemetry arrives.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.errors import DataError


def _multirate(spec, truth, seed=11):
    """x at 100 Hz, h at 25 Hz with a 2 s drop-out at 30-32 s, v at 10 Hz with a gap at 50-51 s."""
    t100 = ri.ra66_times()
    full = ri.simulate_measurements(spec, truth, t100, seed=seed)
    keep = {"x": np.ones(t100.size, bool),
            "h": (np.arange(t100.size) % 4 == 3) & ~((t100 > 30) & (t100 < 32)),
            "v": (np.arange(t100.size) % 10 == 9) & ~((t100 > 50) & (t100 < 51))}
    return ri.Measurements(tuple(ri.Channel(c.name, c.times[keep[c.name]], c.values[keep[c.name]])
                                 for c in full.channels))


@pytest.fixture(scope="module")
def multirate(ra66_spec, ra66_p_true):
    return _multirate(ra66_spec, ra66_p_true)


def _same(a: ri.Measurements, b: ri.Measurements):
    assert a.names == b.names
    for n in a.names:
        np.testing.assert_array_equal(a[n].times, b[n].times)
        np.testing.assert_array_equal(a[n].values, b[n].values)


def test_multirate_csv_and_per_channel_files_read_the_same(tmp_path, multirate):
    path = multirate.to_csv(tmp_path / "multi.csv")
    text = path.read_text().splitlines()
    assert text[0] == "t,x,h,v" and text[1].endswith(",,")      # t = 0.01: only x measured
    _same(ri.read_csv(path), multirate)
    files = {}
    for c in multirate.channels:
        files[c.name] = ri.Measurements((c,)).to_csv(tmp_path / f"{c.name}.csv")
    _same(ri.read_channels(files), multirate)
    assert multirate["h"].times.size == 1601 and multirate["v"].times.size == 651


def test_multirate_fit_matches_per_channel_data_and_truth(tmp_path, ra66_spec, ra66_p_true, multirate):
    from rocketid.estimability import uncertainty

    direct = ri.estimate(ra66_spec, multirate)
    from_csv = ri.estimate(ra66_spec, ri.read_csv(multirate.to_csv(tmp_path / "m.csv")))
    assert direct.success and from_csv.success
    np.testing.assert_allclose(from_csv.p, direct.p, rtol=1e-10, atol=1e-12)
    assert direct.n_data == 6600 + 1601 + 651
    se = uncertainty(direct).standard_errors
    assert np.all(np.abs(direct.p - ra66_p_true) < 4 * se), (direct.p - ra66_p_true) / se
    assert 0.9 < direct.chi2_per_dof < 1.1


def test_cli_reads_multirate_csv(tmp_path, multirate):
    path = multirate.to_csv(tmp_path / "m.csv")
    r = CliRunner().invoke(main, ["estimate", str(path), "--out", str(tmp_path / "f.json")])
    assert r.exit_code == 0, r.output
    assert "8852 values in 3 channels" in r.output


def test_read_channels_bad_input(tmp_path):
    with pytest.raises(DataError, match="non-empty mapping"):
        ri.read_channels({})
    with pytest.raises(DataError, match="does not exist"):
        ri.read_channels({"h": tmp_path / "nope.csv"})
