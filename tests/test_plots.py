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


def test_diagnostics_plots_draw_on_given_axes_return_them_and_keep_the_backend(ra66_noisy_fit, a_foreign_backend,
                                                                                tmp_path):
    """compare, locate, plausibility and history plots: ``ax=None`` / ``axes=None`` gives a figure of
    their own outside pyplot; given axes are drawn on and returned; ``path=`` (or a path in the axes'
    place, the older call) saves the figure."""
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    from rocketid.diagnostics.compare import compare
    from rocketid.diagnostics.history import ModelHistory
    from rocketid.diagnostics.locate import locate
    from rocketid.diagnostics.plausibility import check_plausibility

    open_before = plt.get_fignums()
    comp = compare(ra66_noisy_fit)
    n = len(comp.channels)
    mine = Figure().subplots(n, 2, squeeze=False)
    assert comp.plot(mine) is not None and all(len(a.lines) > 0 for a in mine[:, 0])
    ax = Figure().subplots()
    assert comp.plot_autocorrelation(ax=ax) is ax and ax.lines
    assert comp.plot(tmp_path / "c.png").shape == (n, 2) and (tmp_path / "c.png").stat().st_size > 0
    loc = locate(ra66_noisy_fit, comp)
    axes = loc.plot(path=tmp_path / "l.png")
    assert len(axes) == (4 if loc.conditions else 3) and (tmp_path / "l.png").stat().st_size > 0
    with pytest.raises(Exception, match="panels"):
        loc.plot(Figure().subplots(2, 1))
    pl = check_plausibility(ra66_noisy_fit)
    drawn = pl.plot()
    assert drawn is not None
    hist = ModelHistory().add("base", ra66_noisy_fit)
    own = Figure().subplots(n, 1)
    assert list(hist.plot_residuals(own)) == list(own)
    hist.plot_residuals(path=tmp_path / "h.png")
    assert (tmp_path / "h.png").stat().st_size > 0
    assert plt.get_fignums() == open_before                 # nothing registered with pyplot
    assert matplotlib.get_backend() == a_foreign_backend
