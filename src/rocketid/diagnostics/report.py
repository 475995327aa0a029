"""The diagnosis report: one self-contained HTML file, candidates.json and figures.

``report.html`` needs no network and no other file: the stylesheet is inline
and every plot is a PNG embedded as a ``data:`` URI (matplotlib, Agg). The
page is filled from a :class:`string.Template`; every value put into it is
escaped with :func:`html.escape`. Beside it the writer puts
``candidates.json`` (``{"candidates": [...]}``, best first, each with
``name``, ``statistic``, ``p_value`` (corrected) and ``group``),
``diagnosis.json`` (everything as numbers), ``summary.txt`` and the figures
as PNG files in ``figures/``.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import math
from pathlib import Path
from string import Template
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import SettingsError
from ..output import environment_line, figure_of, new_axes, nulls_for_non_finite, write_bytes, write_json, write_text

__all__ = ["write_report", "render_html", "figure_png", "data_uri", "html_table", "PAGE"]

_CSS = """
:root { --fg: #1d2430; --muted: #5b6472; --line: #d9dee6; --bg: #ffffff; --band: #f5f7fa;
        --fail: #b42318; --warn: #b54708; --ok: #067647; --accent: #1f5fa8; }
* { box-sizing: border-box; }
body { font: 14px/1.45 -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
       color: var(--fg); background: var(--bg); margin: 0; }
main { max-width: 1120px; margin: 0 auto; padding: 24px 28px 60px; }
h1 { font-size: 24px; margin: 0 0 4px; }
h2 { font-size: 19px; margin: 34px 0 8px; padding-top: 10px; border-top: 2px solid var(--line); }
h3 { font-size: 15px; margin: 18px 0 6px; }
p.meta { color: var(--muted); margin: 0 0 14px; }
nav { margin: 10px 0 18px; font-size: 13px; }
nav a { color: var(--accent); margin-right: 14px; text-decoration: none; }
.verdict { border-left: 5px solid var(--accent); background: var(--band); padding: 10px 16px; margin: 12px 0; }
.verdict.bad { border-color: var(--fail); }
.verdict.good { border-color: var(--ok); }
.verdict li { margin: 3px 0; }
table { border-collapse: collapse; margin: 8px 0 14px; font-size: 13px; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 9px; text-align: right; vertical-align: top; }
th { background: var(--band); font-weight: 600; }
td.l, th.l { text-align: left; }
tr.sig td { background: #fff6ed; }
.fail { color: var(--fail); font-weight: 600; }
.warn { color: var(--warn); font-weight: 600; }
.info { color: var(--muted); }
.ok { color: var(--ok); font-weight: 600; }
figure { margin: 10px 0 18px; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: 12.5px; margin-top: 4px; }
pre { background: var(--band); border: 1px solid var(--line); padding: 10px; overflow-x: auto; font-size: 12px;
      line-height: 1.35; }
ol.findings li, ul.notes li { margin: 4px 0; }
details summary { cursor: pointer; color: var(--accent); margin: 6px 0; }
footer { color: var(--muted); font-size: 12px; margin-top: 40px; }
"""

PAGE = Template("""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>$title</title>
<style>$css</style>
</head>
<body>
<main>
<h1>$title</h1>
<p class="meta">$meta</p>
<nav><a href="#compare">1 Compare</a><a href="#locate">2 Locate</a><a href="#plausibility">3 Plausibility</a><a href="#candidates">4 Candidates</a><a href="#steps">4b Stepwise search</a><a href="#confirm">5 Confirmation</a><a href="#history">6 History</a><a href="#fit">Fit</a></nav>
<div class="verdict $verdict_class"><strong>Verdict</strong><ul>$verdict</ul></div>
$notes
<h2 id="compare">1 Compare: measured against model</h2>
$compare
<h2 id="locate">2 Locate: where the model fails</h2>
$locate
<h2 id="plausibility">3 Plausibility of the coefficients</h2>
$plausibility
<h2 id="candidates">4 Candidate effects, ranked by the score test</h2>
$candidates
<h2 id="steps">4b Stepwise search: every contender refitted, accepted only when it explains</h2>
$steps
<h2 id="confirm">5 Confirmation by refitting</h2>
$confirm
<h2 id="history">6 History: the error as effects are added</h2>
$history
<h2 id="fit">The base fit</h2>
<pre>$fit_summary</pre>
<footer>$footer</footer>
</main>
</body>
</html>
""")


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def figure_png(fig, dpi: int = 100) -> bytes:
    """The figure as PNG bytes (the figure is closed afterwards)."""
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


def data_uri(png: bytes) -> str:
    """``data:image/png;base64,...``."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(x, fmt: str = ".4g") -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return _e(x) if x is not None else "-"
    if math.isnan(v):
        return "-"
    return format(v, fmt)


def html_table(header: Sequence[str], rows: Iterable[Sequence[Any]], *, left: int = 1,
               row_classes: Sequence[str] | None = None, text_cols: Sequence[int] = ()) -> str:
    """An HTML table; the first ``left`` columns and those in ``text_cols`` are
    left-aligned; cells are escaped unless given as ``("html", markup)``."""
    def cell(v, i, tag):
        cls = ' class="l"' if i < left or i in text_cols else ""
        if isinstance(v, tuple) and len(v) == 2 and v[0] == "html":
            return f"<{tag}{cls}>{v[1]}</{tag}>"
        return f"<{tag}{cls}>{_e(v)}</{tag}>"
    out = ["<table>", "<tr>" + "".join(cell(h, i, "th") for i, h in enumerate(header)) + "</tr>"]
    for k, r in enumerate(rows):
        cls = f' class="{row_classes[k]}"' if row_classes and row_classes[k] else ""
        out.append(f"<tr{cls}>" + "".join(cell(v, i, "td") for i, v in enumerate(r)) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _compact(names) -> str:
    """``CD_M_1, CD_M_2, CD_M_3`` -> ``CD_M_1..3``: runs of numbered names shortened."""
    import re as _re
    out, run = [], []

    def flush():
        if len(run) > 2:
            out.append(f"{run[0][0]}{run[0][1]}..{run[-1][1]}")
        else:
            out.extend(f"{a}{b}" for a, b in run)
        run.clear()
    for n in map(str, names):
        m = _re.fullmatch(r"(.*?)(\d+)", n)
        if m and run and run[-1][0] == m.group(1) and int(run[-1][1]) + 1 == int(m.group(2)):
            run.append((m.group(1), m.group(2)))
            continue
        flush()
        if m:
            run.append((m.group(1), m.group(2)))
        else:
            out.append(n)
    flush()
    return ", ".join(out)


class _Figures:
    """Collects figures: embeds each as a data URI and writes it to ``figures/``.

    A figure is given as a function that makes it (or as the figure); :meth:`add` returns a
    placeholder, and :meth:`render` makes and renders them all -- half of them in a forked
    worker process when there is more than one core (matplotlib's text layout and PNG encoding
    are most of a report's time) -- and puts each figure's HTML in place of its placeholder.
    """

    def __init__(self, folder: Path | None, workers: int | None = None):
        self.folder = folder
        self.files: list[Path] = []
        self.workers = workers
        self._jobs: list = []

    def add(self, name: str, fig, caption: str) -> str:
        if fig is None:
            return ""
        return self.defer(lambda: _png_of(fig), lambda png: self.add_png(name, png, caption))

    def defer(self, make, html_of, error=None) -> str:
        """A placeholder for ``html_of(make())`` (``make`` returns PNG bytes or None); ``error(exc)``
        is the HTML when ``make`` raises (None: the exception propagates from :meth:`render`)."""
        token = f"\x00figure-{len(self._jobs)}\x00"
        self._jobs.append((token, make, html_of, error))
        return token

    def add_png(self, name: str, png: bytes, caption: str) -> str:
        if self.folder is not None:
            path = write_bytes(self.folder / f"{name}.png", png)
            self.files.append(path)
        return (f'<figure><img alt="{_e(caption)}" src="{data_uri(png)}">'
                f"<figcaption>{_e(caption)}</figcaption></figure>")

    def render(self, page: str) -> str:
        """``page`` with every placeholder replaced by its figure's HTML."""
        results = _make_all([make for _, make, _, _ in self._jobs], self.workers)
        for (token, make, html_of, error), (ok, value) in zip(self._jobs, results):
            if ok:
                text = "" if value is None else html_of(value)
            elif error is not None:
                text = error(value)
            else:
                raise value
            page = page.replace(token, text)
        self._jobs = []
        return page


def _png_of(fig) -> bytes | None:
    """PNG bytes of a figure, or of the figure a function draws (it may return the figure, its
    Axes or an array of them; None: no figure)."""
    if not hasattr(fig, "savefig") and callable(fig):
        fig = fig()
    fig = figure_of(fig)
    return None if fig is None else figure_png(fig)


def _attempt(make) -> tuple:
    try:
        return True, make()
    except Exception as exc:  # noqa: BLE001 - handed to the job's error handler (or re-raised)
        return False, exc


def _make_child(makes, indices, conn, parent_pid) -> None:   # pragma: no cover - runs in a worker process
    """Make the jobs ``indices`` in a forked worker and send ``[(index, value)]`` of those made.

    The worker ends with ``os._exit``: nothing of the parent's (its exit handlers, its
    buffered output) runs twice, and a failure is silent (the parent makes what is missing).
    """
    import os

    from ..sampling.executors import die_with_parent
    code = 1
    try:
        die_with_parent(parent_pid)
        out = []
        for i in indices:
            ok, value = _attempt(makes[i])
            if ok:
                out.append((i, value))
        conn.send(out)
        code = 0
    except BaseException:  # noqa: BLE001 - the parent makes the jobs the worker did not send
        pass
    finally:
        try:
            conn.close()
        finally:
            os._exit(code)


def _make_all(makes: Sequence, workers: int | None = None) -> list:
    """``[(ok, value)]`` of each job, every other one made in a forked worker process when there are
    two cores (a job the worker could not make is made here, so its exception is genuine)."""
    import multiprocessing as mp
    import os

    n = len(makes)
    workers = min(2, os.cpu_count() or 1) if workers is None else int(workers)
    results: list = [None] * n
    proc = recv = None
    mine = list(range(n))
    if workers > 1 and n > 1 and "fork" in mp.get_all_start_methods():
        ctx = mp.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        theirs = list(range(1, n, 2))
        proc = ctx.Process(target=_make_child, args=(makes, theirs, send, os.getpid()), daemon=True)
        try:
            proc.start()
            mine = list(range(0, n, 2))
        except OSError:
            proc = None
        send.close()
    try:
        for i in mine:
            results[i] = _attempt(makes[i])
        if proc is not None:
            try:
                for i, value in recv.recv():
                    results[i] = (True, value)
            except (EOFError, OSError):
                pass
            proc.join(10.0)
    finally:
        if proc is not None:
            if proc.is_alive():
                proc.terminate()
                proc.join(5.0)
            recv.close()
    for i in range(n):
        if results[i] is None:
            results[i] = _attempt(makes[i])
    return results


# ---------------------------------------------------------------------------
# sections
# ---------------------------------------------------------------------------


def _compare_section(comp, figs: _Figures, name: str = "compare", heading: str = "") -> str:
    rows = []
    for c in comp.channels:
        rows.append([c.name, c.n, _num(c.sigma, ".3g"), _num(c.rms), _num(c.bias, "+.3g"), _num(c.bias_z, "+.3g"),
                     _num(c.chi2_per_dof), f"{c.theil.U:.2e}", _num(c.theil.bias, ".2f"), _num(c.theil.variance, ".2f"),
                     _num(c.theil.covariance, ".2f"), f"{100 * c.outside_2sigma:.1f} %",
                     _num(c.whiteness.statistic, ".4g"), _num(c.whiteness.p_value, ".2g"),
                     _num(c.whiteness.lag1, ".3f"), _num(c.normality.statistic, ".4g"),
                     _num(c.normality.p_value, ".2g")])
    crit = comp.criterion
    parts = [heading,
             f"<p>chi2/dof = <strong>{_num(comp.chi2_per_dof)}</strong> over {comp.n_data} values and "
             f"{comp.n_estimated} estimated quantities; white noise: "
             + ('<span class="ok">yes</span>' if comp.fits_to_noise else '<span class="fail">no</span>')
             + ". Residual = model &minus; measured; e = residual / sigma.</p>",
             html_table(["channel", "n", "sigma", "RMS", "bias", "bias z", "chi2/dof", "Theil U", "U_M", "U_S", "U_C",
                         "|e| > 2", "Ljung-Box Q", "LB p", "lag-1 rho", "Jarque-Bera", "JB p"], rows),
             "<h3>Statistic criterion eta (7.10)</h3>",
             html_table(["eta", "|s1|", "|k1-3|", "|s1-s2|", "|k1-k2|", "s1", "k1", "s2", "k2"],
                        [[_num(crit[k]) for k in ("eta", "|s1|", "|k1-3|", "|s1-s2|", "|k1-k2|", "s1", "k1", "s2", "k2")]],
                        left=0),
             f"<p class=\"info\">eta computed by {_e(comp.criterion_source)}. eta tests skewness and kurtosis, "
             "not whiteness: the Ljung-Box test (20 lags) is the whiteness test.</p>",
             figs.add(name, comp.plot, "Per channel: measured and model against time (left); normalized residual "
                                          "with the +-2 sigma band and a 1 s running mean (right)."),
             figs.add(f"{name}_acf", comp.plot_autocorrelation,
                      "Autocorrelation of the normalized residuals against the lag, with the +-2/sqrt(n) band of white noise.")]
    if comp.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in comp.notes) + "</ul>")
    return "\n".join(parts)


def _locate_section(loc, figs: _Figures) -> str:
    if loc is None:
        return '<p class="warn">No location: the data are too short for the windows (see the notes above).</p>'
    parts = [f"<p>Windows of {loc.window:.3g} s every {loc.step:.3g} s; a window fails when |z| &gt; "
             f"{loc.z_critical:.2f} or its scatter exceeds sigma (level {loc.level:g}, Bonferroni over "
             f"{loc.n_tests} tests).</p>"]
    if loc.findings:
        parts.append("<h3>Failing windows, in words</h3><ol class=\"findings\">"
                     + "".join(f"<li>{_e(f.text)}</li>" for f in loc.findings[:10]) + "</ol>")
        if len(loc.findings) > 10:
            parts.append(f"<p class=\"info\">{len(loc.findings) - 10} more findings in diagnosis.json.</p>")
    else:
        parts.append('<p class="ok">No window fails: the residuals look like white noise everywhere.</p>')
    if loc.phases:
        chans = list(loc.windows)
        rows = []
        for p in loc.phases:
            row = [p.name, f"{p.t_start:.1f}-{min(p.t_end, loc.condition_times[-1]):.1f}"]
            for c in chans:
                r = next((x for x in loc.phase_table if x["phase"] == p.name and x["channel"] == c), None)
                if r is None:
                    row += ["-", "-"]
                else:
                    z = r["z"]
                    cls = "fail" if abs(z) > loc.z_critical else ""
                    row += [("html", f'<span class="{cls}">{z:+.1f}</span>'), f"{r['rms_ratio']:.2f}"]
            rows.append(row)
        head = ["phase", "t (s)"] + [h for c in chans for h in (f"{c} bias z", f"{c} std(e)")]
        parts += ["<h3>Per flight phase</h3>", html_table(head, rows, left=2)]
    cus = [[c.channel, f"{c.change_time:.1f}", _num(c.statistic, ".3g"), _num(c.p_value, ".2g"),
            "-" if c.departure_time is None else f"{c.departure_time:.1f}"] for c in loc.cusums.values()]
    parts += ["<h3>Cumulative sums</h3>",
              html_table(["channel", "change point t (s)", "max |bridge|", "p (white noise)",
                          "leaves the +-3 band at t (s)"], cus),
              figs.add("locate", loc.plot, "Window bias z (flagged windows marked), scatter ratio, cumulative sums "
                                             "with the +-2 sqrt(k/n) band of white noise, and the flight conditions; "
                                             "flight phases shaded.")]
    if loc.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in loc.notes) + "</ul>")
    return "\n".join(parts)


def _plausibility_section(pl, figs: _Figures) -> str:
    verdict = ('<span class="ok">plausible</span>' if pl.passed else '<span class="fail">implausible</span>')
    parts = [f"<p>Verdict: {verdict}.</p>"]
    if pl.flags:
        parts.append(html_table(["#", "severity", "check", "parameters", "finding"],
                                [[i, ("html", f'<span class="{f.severity}">{_e(f.severity)}</span>'), f.code,
                                  ", ".join(f.parameters), f.message] for i, f in enumerate(pl.flags, 1)], left=5))
    flagged = set(pl.flagged_parameters())
    rows, cls = [], []
    for i, n in enumerate(pl.names):
        rows.append([n, pl.kinds[i], _num(pl.estimates[i], ".5g"), _num(pl.standard_errors[i], ".3g"),
                     _num(pl.lower[i], ".3g"), _num(pl.upper[i], ".3g"),
                     ", ".join(sorted({f.code for f in pl.flags if n in f.parameters})) or "-"])
        cls.append("sig" if n in flagged else "")
    parts += ["<h3>Coefficients</h3>",
              html_table(["parameter", "kind", "estimate", "std err", "lower", "upper", "flags"], rows, left=2,
                         row_classes=cls)]
    for mc in pl.mach_checks:
        parts.append(f"<h3>Is {_e(mc.family)}(t) a smooth function of Mach?</h3>"
                     f"<p>Best {_e(mc.family_name)} through the knots, with covariance C + tau^2 I (tau = "
                     f"{mc.tolerance:g}): chi2 = {mc.statistic:.3g} on {mc.dof} dof, "
                     f"p = <strong>{mc.p_value:.2g}</strong>.</p>")
        parts.append(html_table(["knot", "t (s)", "Mach", "value", "std err", "smooth curve", "std. residual"],
                                [[k, f"{t:.1f}", f"{m:.2f}", f"{v:.4f}", _num(s, ".2g"), f"{c:.4f}", f"{z:+.2f}"]
                                 for k, t, m, v, s, c, z in zip(mc.knots, mc.times, mc.mach, mc.values,
                                                                mc.standard_errors, mc.smooth, mc.standardized)]))
    parts.append(figs.add("plausibility", pl.plot,
                          "Time-knot drag against the Mach number at the knot times, with the best smooth drag curve "
                          "and +-2 sqrt(se^2 + tau^2) bars (left), and against time (right); flagged knots in red."
                          if pl.mach_checks else "Estimates between their bounds with 2-sigma bars; flagged in red."))
    if pl.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in pl.notes) + "</ul>")
    return "\n".join(parts)


def _ranking_plot(ranking):
    cands = list(ranking.candidates)[:15]
    if not cands:
        return None
    ax = new_axes((8, 0.32 * len(cands) + 1.2))
    fig = ax.figure
    y = np.arange(len(cands))[::-1]
    stat = np.array([max(float(c.statistic), 1e-3) for c in cands])
    col = ["tab:red" if getattr(c, "significant", False) else "tab:gray" for c in cands]
    ax.barh(y, stat, color=col)
    groups = list(getattr(ranking, "groups", []) or [])

    def label(c):
        g = getattr(c, "group", None)
        members = groups[g - 1] if isinstance(g, int) and 0 < g <= len(groups) else []
        return c.name + (f"  [group {g}]" if len(members) > 1 else "")

    ax.set_yticks(y, [label(c) for c in cands], fontsize=8)
    for yi, st in zip(y, stat):
        ax.text(st, yi, f" {st:.3g}", va="center", fontsize=7)
    ax.set_xlim(0, stat.max() * 1.18)
    ax.set_xlabel("score statistic (red: significant after correction)")
    fig.tight_layout()
    return fig


def _candidates_section(report, figs: _Figures) -> str:
    r = report.ranking
    if r is None:
        return '<p class="warn">No ranking (see the notes above).</p>'
    rows, cls = [], []
    for i, c in enumerate(r.candidates, 1):
        absorbed = getattr(c, "absorbed_by", None)
        if isinstance(absorbed, (list, tuple)):
            absorbed = _compact(absorbed)
        rows.append([i, c.name, getattr(c, "title", ""), _num(c.statistic, ".4g"), getattr(c, "dof", "-"),
                     _num(getattr(c, "p_value", None), ".2g"), _num(getattr(c, "p_value_corrected", None), ".2g"),
                     _num(getattr(c, "predicted_drop", None), ".4g"), getattr(c, "group", "") or "-",
                     absorbed or "-", "yes" if getattr(c, "significant", False) else "no",
                     getattr(c, "note", "") or ""])
        cls.append("sig" if getattr(c, "significant", False) else "")
    parts = [f"<p>Score (Lagrange-multiplier) test of each candidate at the base fit, best first; p-values "
             f"corrected for the number of candidates; significant at {report.level:g} highlighted. "
             "Candidates in one group are confounded: decide between them by refitting.</p>",
             html_table(["#", "effect", "title", "statistic", "dof", "p", "p corrected", "predicted drop", "group",
                         "absorbed by", "significant", "note"], rows, left=3, row_classes=cls,
                        text_cols=(9, 11))]
    groups = getattr(r, "groups", None)
    if groups:
        try:
            items = list(groups.items() if hasattr(groups, "items") else enumerate(groups, 1))
            multi = [(k, v) for k, v in items if not isinstance(v, (list, tuple)) or len(v) > 1]
            if multi:
                parts.append("<h3>Confounded groups</h3><p>The data cannot tell the members of a group apart at "
                             "the base fit; the refits decide.</p><ul>" + "".join(
                                 f"<li>group {_e(k)}: {_e(', '.join(map(str, v)) if isinstance(v, (list, tuple)) else v)}"
                                 "</li>" for k, v in multi) + "</ul>")
        except Exception:  # noqa: BLE001 - an unexpected shape is shown as text
            parts.append(f"<pre>{_e(groups)}</pre>")
    parts.append(figs.add("candidates", lambda: _ranking_plot(r), "Score statistic of each candidate; red: significant after the correction."))
    try:
        parts.append(f"<details><summary>ranking summary</summary><pre>{_e(r.summary())}</pre></details>")
    except Exception:  # noqa: BLE001
        pass
    return "\n".join(parts)


def _confirm_section(report, figs: _Figures) -> str:
    if not report.confirmations:
        return "<p>No candidate was refitted" + (" (none is significant)." if report.ranking is not None else ".") + "</p>"
    rows, cls = [], []
    pls = list(report.refit_plausibility) if len(report.refit_plausibility) == len(report.confirmations) \
        else [None] * len(report.confirmations)
    for c, name, pl in zip(report.confirmations, report.confirmed, pls):
        est = "; ".join(f"{k} = {v:.4g} +- {s:.2g} [{lo:.4g}, {hi:.4g}]"
                        for k, (v, s, (lo, hi)) in c.effect_estimates.items())
        hold = ("-" if not c.holdout_rms else
                ", ".join(f"{k} {a:.3g} -> {b:.3g}" for k, (a, b) in c.holdout_rms.items()))
        white = ", ".join(f"{k} {_num(a, '.2g')} -> {_num(b, '.2g')}" for k, (a, b) in c.whiteness.items())
        rows.append([name, ("html", '<span class="ok">confirmed</span>' if c.confirmed
                            else '<span class="fail">not confirmed</span>'), est,
                     f"{c.chi2_per_dof[0]:.4g} -> {c.chi2_per_dof[1]:.4g}", _num(c.lr_statistic, ".4g"),
                     _num(c.lr_p_value, ".2g"), f"{c.bic[1] - c.bic[0]:+.5g}", white, hold,
                     "-" if pl is None else ("plausible" if pl.passed else
                                             "implausible: " + ", ".join(pl.flagged_parameters()))])
        cls.append("sig" if c is report.best else "")
    hold_txt = (f"fit {report.confirmations[0].holdout[0]:g}-{report.confirmations[0].holdout[1]:g} s, predict the rest"
                if report.confirmations[0].holdout else "no hold-out")
    parts = [f"<p>Each leading candidate added to the model and refitted from nominal values: likelihood-ratio "
             f"test against the base fit, the change of BIC (negative is better), Ljung-Box p before and after, and "
             f"the hold-out check ({_e(hold_txt)}: prediction RMS, base -> new). Highlighted: the chosen refit.</p>",
             html_table(["effect", "verdict", "estimate (95 % interval)", "chi2/dof", "LR statistic", "LR p",
                         "delta BIC", "Ljung-Box p", "hold-out RMS", "coefficients"], rows, left=3,
                        row_classes=cls, text_cols=(7, 8, 9))]
    if report.best is not None:
        parts.append(f"<p>Chosen: <strong>{_e(report.effect_name(report.best))}</strong> ({_e(report.choice)}).</p>")
    for c in report.confirmations:
        try:
            parts.append(f"<details><summary>{_e(c.summary().splitlines()[0])}</summary><pre>{_e(c.summary())}</pre>"
                         "</details>")
        except Exception:  # noqa: BLE001
            pass
    if report.after is not None:
        best = report.best
        parts.append(f"<h3>After: the model with {_e(report.effect_name(best))}</h3>")
        parts.append(_compare_section(report.after, figs, name="after"))
    return "\n".join(parts)


def _free_shape_plot(free):
    """The free shape's values at its knots (:class:`~rocketid.diagnostics.freeshape.FreeShape`), below the model's
    thrust and the thrust with the shape for a thrust error."""
    drag = getattr(free, "drag", ())
    if drag:
        top, ax = new_axes((8, 5), 2, 1)
        top.plot(drag[0], drag[1], color="0.5", label="the model's drag coefficient (the base fit)")
        top.plot(drag[2], drag[3], color="tab:red", label="with the free shape (its fit)")
        top.set_xlabel("Mach")
        top.set_ylabel("drag coefficient")
        top.legend(fontsize=8)
        top.set_title(f"{free.effect}: chi2/dof {free.chi2_per_dof:.4g}", fontsize=9)
    elif free.curve:
        top, ax = new_axes((8, 5), 2, 1, sharex=True)
        t, stated, fitted = (np.asarray(c) for c in free.curve)
        top.plot(t, stated / 1e3, color="0.5", label="the model's thrust (along the base fit)")
        top.plot(t, fitted / 1e3, color="tab:red", label="with the free shape")
        top.set_ylabel("thrust (kN)")
        top.legend(fontsize=8)
        top.set_title(f"{free.effect}: chi2/dof {free.chi2_per_dof:.4g}", fontsize=9)
    else:
        ax = new_axes((8, 3))
        ax.set_title(f"{free.effect}: chi2/dof {free.chi2_per_dof:.4g}", fontsize=9)
    percent = free.kind in ("propulsion", "mass") or free.effect.startswith("density")
    y = 100 * np.asarray(free.values) if percent else np.asarray(free.values)
    pins = tuple(getattr(free, "pins", ()))
    if pins and free.values:                 # a drag correction held at zero on the table's knots, between them free
        both = sorted([(k, v) for k, v in zip(free.knots, y)] + [(z, 0.0) for z in pins])
        ax.plot([k for k, _ in both], [v for _, v in both], "-", color="tab:blue", lw=1)
        ax.plot(free.knots, y, "o", ms=3, color="tab:blue")
        ax.plot(pins, np.zeros(len(pins)), "o", ms=4, mfc="white", color="tab:blue",
                label="held at 0 (the table's knots)")
        ax.legend(fontsize=7)
    else:
        ax.plot(free.knots, y, "o-", ms=3)
    ax.axhline(0.0, color="0.6", lw=0.8)
    first = getattr(free, "first_sample", float("nan"))
    if np.isfinite(first) and free.knots and free.knots[0] < first:    # no data yet: the values placed only together
        for a in ((top, ax) if free.curve else (ax,)):
            a.axvspan(free.knots[0], first, color="0.9", zorder=0)
        ax.text(0.5 * (free.knots[0] + first), 0.03, "no data\nyet", transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=7, color="0.4")
    if free.unit == "s" and len(free.knots) > 1:             # the burn, not the coast after it
        ax.set_xlim(free.knots[0], free.knots[-1] + 0.1 * (free.knots[-1] - free.knots[0]))
    ax.set_xlabel({"s": "t (s)", "km": "altitude (km)", "Mach": "Mach"}.get(free.unit, free.unit))
    ax.set_ylabel({"propulsion": "thrust error (%)", "mass": "thrust error (%)"}.get(
        free.kind, "density deviation (%)" if percent else "wind (m/s)" if free.effect.startswith("wind")
        else "drag coefficient change"))
    ax.figure.tight_layout()
    return ax.figure


def _steps_section(report, figs: _Figures) -> str:
    steps = getattr(report, "steps", ())
    final = getattr(report, "final", None)
    parts = []
    if final is not None:
        cls = "ok" if final.verdict in ("explained", "nothing missing") else "fail"
        parts.append(f'<p>Final verdict: <span class="{cls}">{_e(final.verdict)}</span>. {_e(final.explanation)}</p>')
    free = getattr(report, "free_shape", None)
    if free is not None:
        parts.append(f"<p>{_e(free.text())}</p>")
        if free.values:
            parts.append(figs.add("free_shape", lambda: _free_shape_plot(free),
                                  (f"The free shape {free.effect}: the model's thrust and the thrust with it "
                                   "(above), its values at its knots (below)" if free.curve else
                                   f"The free shape {free.effect}: the model's drag coefficient against Mach and "
                                   "that of the fit with it (above), its values at its knots (below)"
                                   if getattr(free, "drag", ()) else
                                   f"The free shape {free.effect}: its values at its knots")
                                  + (f" (fitted beside {', '.join(free.kept)})" if free.kept else "")))
    if not steps:
        parts.append("<p>No stepwise search was run (rank only, or the discovery failed: see the notes).</p>")
        return "\n".join(parts)
    band = report.discovery.band
    parts.append(f"<p>Each contender is added to the model and refitted. <strong>Accepted</strong>: converged, "
                 f"LR-significant (Bonferroni over the contenders), BIC lower, chi2/dof inside the noise band "
                 f"(&le; {band.upper:.4g}: {band.dof} dof, discretization {_num(band.discretization, '.3g')}), residuals "
                 "white (Ljung-Box, Holm over the channels, p &ge; 0.001), plausible coefficients and an effect size "
                 "within 5 realistic sizes for this vehicle. <strong>Admissible</strong>: all but the noise and "
                 "whiteness (a step toward the explanation). Highlighted: the refit taken at each step.</p>")
    for s in steps:
        rows, cls = [], []
        for a in s.acceptances:
            r = a.refit
            b0, b1 = r.bic if r.success else (float("nan"), float("nan"))
            est = "; ".join(f"{n} = {r.estimate(n)[0]:.4g} +- {r.estimate(n)[1]:.2g}" for n in r.effect_parameters)
            state = ('<span class="ok">accepted</span>' if a.accepted else
                     ('<span class="warn">admissible</span>' if a.admissible else '<span class="fail">rejected</span>'))
            rows.append([r.name, ("html", state), _num(r.chi2_per_dof, ".4g"), f"{b1 - b0:+.5g}",
                         _num(r.lr_p_value, ".2g"), est or "-", a.reason() or "-"])
            cls.append("sig" if s.chosen is a else "")
        parts.append(f"<h3>Step {s.number}: {_e(s.why)}</h3>")
        if s.dropped:
            parts.append(f"<p>The backward check dropped {_e(', '.join(s.dropped))}.</p>")
        parts.append(html_table(["effect", "verdict", "chi2/dof", "delta BIC", "LR p", "estimate", "why not accepted"],
                                rows, left=1, row_classes=cls, text_cols=(5, 6)))
        if s.fit is not None:
            parts.append(f"<p>After step {s.number}: {_e(', '.join(s.effects))}, chi2/dof {s.fit.chi2_per_dof:.4g}.</p>")
    return "\n".join(parts)


def _history_section(report, figs: _Figures) -> str:
    h = report.history
    if h is None:
        return "<p>No history (see the notes above).</p>"
    parts = []
    try:
        parts.append(f"<pre>{_e(h.table())}</pre>")
    except Exception as exc:  # noqa: BLE001
        parts.append(f"<p class=\"warn\">history table unavailable: {_e(exc)}</p>")
    if figs.folder is not None:
        path = figs.folder / "history.png"

        def make():
            h.plot_residuals(path=path)
            return path.read_bytes() if path.is_file() else None

        def html_of(png):
            figs.files.append(path)
            return (f'<figure><img alt="history residuals" src="{data_uri(png)}">'
                    "<figcaption>Residuals of the base model and after each step of the stepwise search: "
                    "samples and 1 s moving average.</figcaption></figure>")

        # a report must not fail on one plot
        parts.append(figs.defer(make, html_of, lambda exc: f"<p class=\"warn\">history plot unavailable: {_e(exc)}</p>"))
    return "\n".join(parts)


# ---------------------------------------------------------------------------
# the page
# ---------------------------------------------------------------------------


def render_html(report, figures_folder: Path | None = None) -> tuple[str, list[Path]]:
    """The report's HTML (self-contained) and the figure files written."""
    figs = _Figures(figures_folder)
    fit = report.fit
    notes = report.notes
    verdict = "".join(f"<li>{_e(s)}</li>" for s in report.verdict())
    notes_html = ("<h3>Notes</h3><ol>" + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ol>") if notes else ""
    meta = (f"Model {_e(report.model)} ({_e(fit.spec.name)}), data {_e(report.data_label)}: "
            f"{fit.n_data} values in {len(fit.nlp.channel_names)} channels; level {report.level:g}; "
            f"fit {'converged' if fit.success else 'NOT converged'} in {fit.iterations} iterations.")
    tm = ", ".join(f"{k[:-2]} {v:.2f} s" for k, v in report.timings.items())
    page = PAGE.substitute(
        title=_e(f"rocketid diagnosis: {fit.spec.name}"), css=_CSS, meta=meta,
        verdict_class="bad" if report.fails else "good", verdict=verdict, notes=notes_html,
        compare=_compare_section(report.comparison, figs), locate=_locate_section(report.location, figs),
        plausibility=_plausibility_section(report.plausibility, figs), candidates=_candidates_section(report, figs),
        steps=_steps_section(report, figs),
        confirm=_confirm_section(report, figs), history=_history_section(report, figs),
        fit_summary=_e(str(fit.summary())),
        footer=_e(f"Made on {_dt.datetime.now().strftime('%Y-%m-%d %H:%M')} by {environment_line()}; "
                  f"timings: {tm}. Self-contained: no network needed."))
    return figs.render(page), figs.files


def write_report(report, out: str | Path) -> Path:
    """Write the report's files into the folder ``out`` (created); returns report.html's path."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SettingsError(f"cannot create the report folder {str(out)!r}: {exc.strerror or exc}") from None
    if not out.is_dir():
        raise SettingsError(f"{str(out)!r} is not a folder")
    # everything is formed before the first file is replaced, and every file is written atomically
    page, _ = render_html(report, out / "figures")
    payloads = {name: nulls_for_non_finite(json.loads(json.dumps(obj, default=_json_default)))
                for name, obj in (("candidates.json", report.candidates_payload()),
                                  ("diagnosis.json", report.to_dict()))}
    summary = report.summary() + "\n"
    for name, obj in payloads.items():
        write_json(out / name, obj)
    write_text(out / "summary.txt", summary)
    return write_text(out / "report.html", page)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    return str(o)
