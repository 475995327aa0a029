"""Plots draw on the caller's axes, return them, and leave the matplotlib backend alone (unit tier)."""

from __future__ import annotations

import matplotlib
import pytest

from rocketid.estimability import analyze


@pytest.fixture
def a_foreign_backend():
    """The user's backend: plots must not switch it."""
    before = matplotlib.get_backend()
    matplotlib.use("pdf")
    yield "pdf"
    matplotlib.use(before)


def test_estimability_plots_use_the_given_axes_and_keep_the_backend(ra66_noisy_fit, a_foreign_backend, tmp_path):
    from matplotlib.figure import Figure
    est = analyze(ra66_noisy_fit.prepared, scaling="nominal")
    fig = Figure()
    a1, a2 = fig.subplots(1, 2)
    assert est.plot_spectrum(a1) is a1 and est.plot_directions(ax=a2) is a2
    assert len(a1.patches) == est.eigenvalues.size  # one bar per direction
    assert [t.get_text() for t in a2.get_yticklabels()] == list(est.parameter_names)
    own = est.plot_spectrum()
    assert own.figure is not fig
    whole = est.plot(tmp_path / "est.png")
    assert (tmp_path / "est.png").stat().st_size > 0 and len(whole.axes) == 3  # two panels and a colour bar
    assert matplotlib.get_backend() == a_foreign_backend
