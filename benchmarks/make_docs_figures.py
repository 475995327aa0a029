"""Make the figures of docs/diagnose-tutorial.md, docs/time-knot-trap.md and the free shape of docs/effects.md.

    python3 benchmarks/make_docs_figures.py              # all
    python3 benchmarks/make_docs_figures.py --trap        # only the time-knot trap
    python3 benchmarks/make_docs_figures.py --tutorial    # only the tutorial
    python3 benchmarks/make_docs_figures.py --free-shape  # only the free shape on Wren-H's hot tank

Runs the pages' own code (the same data, models and calls) and writes PNG files
into docs/figures/, printing the numbers the pages quote. Takes about a minute.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import rocketid as ri
from rocketid.cases import RA66M_CD_TRUTH, RA66M_MACH_KNOTS, ra66m, ra66m_truth
from rocketid.cases.ra66m import ra66m_alpha
from rocketid.diagnostics.compare import compare
from rocketid.diagnostics.effects import with_effects
from rocketid.diagnostics.locate import locate
from rocketid.diagnostics.plausibility import check_plausibility
from rocketid.model import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

FIGURES = Path(__file__).resolve().parents[1] / "docs" / "figures"
A_E = 0.1      # m^2: A_e p0 = 10 kN, 2.5 % of the 400 kN thrust
SEED = 0


def tutorial_data():
    """RA-66M measurements with a hidden nozzle back-pressure (the pages' data)."""
    truth_spec = with_effects(ra66m(), "back_pressure", {"A_e": A_E})
    return ri.simulate_measurements(truth_spec, ra66m_truth(truth_spec), ri.ra66_times(), seed=SEED)


def time_knot_model(lower: float = 1e-4, upper: float = 1.0):
    """RA-66M's vehicle and attack-angle input with the chapter's drag: CD(t) piecewise
    linear in time on 7 knots (0, 11, ..., 66 s); lift CL_alpha alpha (as docs/time-knot-trap.md)."""
    m = Model("RA-66M, time-knot drag", 0.0, 66.0)
    st = ascent_states(m)
    fc = flight_conditions(m, st)
    alpha = m.input("alpha", ra66m_alpha(m.t), breakpoints=(4.0, 24.0))
    cd = m.piecewise_linear("CD", np.linspace(0.0, 66.0, 7), 0.4, bounds=(lower, upper), nominal=0.5)
    cl_alpha = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
    ascent_dynamics(m, st, fc, thrust=m.constant("Pe", 400000.0),
                    mass=m.constant("m0", 20000.0) - m.constant("mdot", 100.0) * m.t,
                    area=m.constant("Sm", math.pi), cd=cd, cl=cl_alpha * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=1.0)
    return m.freeze()


def _save(drawn, name):
    """Save what a plot drew (a figure, its Axes or an array of them)."""
    from rocketid.output import figure_of
    fig = figure_of(drawn)
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURES / name, dpi=90)
    plt.close(fig)
    print(f"  wrote docs/figures/{name}")


def _rms_split(comp, t_split=10.0):
    return {c.name: (float(np.sqrt(np.mean(c.normalized[c.times <= t_split] ** 2))),
                     float(np.sqrt(np.mean(c.normalized[c.times > t_split] ** 2)))) for c in comp.channels}


def _true_cd(mach):
    return np.interp(mach, RA66M_MACH_KNOTS, RA66M_CD_TRUTH)


def trap_figures():
    print("time-knot trap")
    data = tutorial_data()
    fits = {"Mach-indexed (RA-66M)": ri.estimate(ra66m(), data),
            "time knots, chapter's bounds": ri.estimate(time_knot_model(), data),
            "time knots, wide bounds": ri.estimate(time_knot_model(-5.0, 10.0), data)}
    for label, fit in fits.items():
        comp = compare(fit)
        pl = check_plausibility(fit)
        split = _rms_split(comp)
        print(f"  {label:30s} chi2/dof {fit.chi2_per_dof:8.4g}; RMS(e) h t<=10 s {split['h'][0]:.3g}, t>10 s "
              f"{split['h'][1]:.3g}; x t>10 {split['x'][1]:.3g}; v t>10 {split['v'][1]:.3g}; plausible {pl.passed}; "
              f"p = {np.array2string(fit.p, precision=3)}")
    wide = fits["time knots, wide bounds"]
    comp = compare(wide)
    _save(comp.plot(title="time-knot drag, wide bounds: residuals near the noise level after the first 12 s"),
          "trap-compare.png")
    pl = check_plausibility(wide)
    print(pl.summary())
    mc = pl.mach_checks[0]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    mm = np.linspace(0, 3.0, 300)
    a1.plot(mm, _true_cd(mm), "-", color="tab:green", lw=2, label="true CD(M) of the data")
    a1.plot(mm, mc.curve(mm), "--", color="0.3", label=f"best smooth drag curve (p = {mc.p_value:.1g})")
    bar = 2 * np.sqrt(mc.standard_errors ** 2 + mc.tolerance ** 2)
    a1.errorbar(mc.mach, mc.values, yerr=bar, fmt="o", color="tab:red", capsize=3, label="time knots CD0..CD6")
    for k, m_, v in zip(mc.knots, mc.mach, mc.values):
        a1.annotate(k, (m_, v), textcoords="offset points", xytext=(5, 3), fontsize=8)
    a1.set_xlabel("Mach number at the knot time")
    a1.set_ylabel("drag coefficient")
    a1.set_ylim(-0.2, max(6.5, mc.values.max() + 0.5))
    a1.legend(fontsize=8)
    a1.set_title("the knots against Mach", fontsize=10)
    chap = fits["time knots, chapter's bounds"]
    tk = np.linspace(0, 66, 7)
    a2.plot(tk, mc.values, "o-", color="tab:red", label="wide bounds")
    a2.plot(tk, chap.p[:7], "s-", color="tab:orange", label="chapter's bounds (1e-4 .. 1)")
    mach_t = ri.simulate(ra66m(), ra66m_truth(ra66m()), np.linspace(0, 66, 200)).value("mach")
    a2.plot(np.linspace(0, 66, 200), _true_cd(mach_t), "-", color="tab:green", lw=2, label="true CD(M(t))")
    a2.set_xlabel("t (s)")
    a2.set_ylabel("CD(t)")
    a2.set_yscale("log")
    a2.legend(fontsize=8)
    a2.set_title("the knots against time", fontsize=10)
    fig.suptitle("time-knot drag on back-pressure data: CD0 absorbs the thrust deficit at lift-off", fontsize=11)
    fig.tight_layout()
    _save(fig, "trap-cd-vs-mach.png")
    # the same checks on correct data
    clean = ri.simulate_measurements(ra66m(), ra66m_truth(ra66m()), ri.ra66_times(), seed=SEED)
    ok = ri.estimate(time_knot_model(-5.0, 10.0), clean)
    pl_ok = check_plausibility(ok)
    strict = check_plausibility(ok, mach_tolerance=0.0)
    quad = check_plausibility(ok, transonic=False)
    print(f"  no hidden effect: chi2/dof {ok.chi2_per_dof:.4g}, plausible {pl_ok.passed}, Mach p "
          f"{pl_ok.mach_checks[0].p_value:.2g} (tau 0: {strict.mach_checks[0].p_value:.2g}; quadratic only: "
          f"{quad.mach_checks[0].p_value:.2g}); knots {np.array2string(ok.p[:7], precision=3)}")


def tutorial_figures():
    print("tutorial")
    data = tutorial_data()
    t0 = time.perf_counter()
    fit = ri.estimate(ra66m(), data)
    comp = compare(fit)
    _save(comp.plot(title=f"RA-66M on data with a hidden effect: chi2/dof {fit.chi2_per_dof:.3g}"),
          "tutorial-compare-before.png")
    loc = locate(fit, comp)
    _save(loc.plot(), "tutorial-locate.png")
    print("\n".join(loc.sentences(3)))
    pl = check_plausibility(fit)
    _save(pl.plot(), "tutorial-plausibility.png")
    try:
        from rocketid.diagnostics.score import rank_candidates
    except ImportError as exc:
        print(f"  no ranking figures: {exc}")
        return
    ranking = rank_candidates(fit)
    print(ranking.summary())
    from rocketid.diagnostics.report import _ranking_plot
    _save(_ranking_plot(ranking), "tutorial-candidates.png")
    try:
        from rocketid.diagnostics.history import ModelHistory
        from rocketid.diagnostics.refit import confirm
    except ImportError as exc:
        print(f"  no refit figures: {exc}")
        return
    conf = confirm(fit, "back_pressure")
    print(conf.summary())
    alt = confirm(fit, "thrust_level")
    print(alt.summary())
    after = compare(conf.fit)
    _save(after.plot(title=f"RA-66M + back_pressure: chi2/dof {conf.fit.chi2_per_dof:.3g}"),
          "tutorial-compare-after.png")
    history = ModelHistory().add("RA-66M", fit).add("+ back_pressure", conf.fit)
    print(history.table())
    _save(history.plot_residuals(), "tutorial-history.png")
    plt.close("all")
    print(f"  tutorial loop in {time.perf_counter() - t0:.1f} s")


def free_shape_figure():
    """Wren-H's hot tank (the hybrid study's truth and seed): the free shape a partly explained search fits."""
    import sys
    from types import SimpleNamespace
    tests = Path(__file__).resolve().parents[1] / "tests"
    sys.path[:0] = [str(tests), str(tests / "vehicles")]
    import wren
    from wren_study import truth
    from wren_study.cases import BY_NAME
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.freeshape import free_shape_check
    from rocketid.diagnostics.report import _free_shape_plot
    from rocketid.diagnostics.screen import vehicle_of
    case = BY_NAME["hot-tank"]
    fit, _, counts, _, _ = base_fit(wren.build_model(), truth.measurements(case.hidden, seed=case.seed), "estimate")
    disc = SimpleNamespace(base_fit=fit, fit=fit, band=noise_band(fit, estimated=counts), vehicle=vehicle_of(fit),
                           effects=())
    fs = free_shape_check(disc, "propulsion", "thrust_level")
    print(f"  hot tank: base chi2/dof {fit.chi2_per_dof:.4g}; {fs.effect} {fs.chi2_per_dof:.4g}; {fs.reading}")
    _save(_free_shape_plot(fs), "free-shape-hot-tank.png")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trap", action="store_true")
    ap.add_argument("--tutorial", action="store_true")
    ap.add_argument("--free-shape", action="store_true")
    a = ap.parse_args()
    every = not (a.trap or a.tutorial or a.free_shape)
    if a.trap or every:
        trap_figures()
    if a.tutorial or every:
        tutorial_figures()
    if a.free_shape or every:
        free_shape_figure()


if __name__ == "__main__":
    main()
