"""Locate: where the model fails, in time, flight phase and flight condition.

The second step of the diagnosis loop. The normalized residuals ``e = (model
- measured) / sigma`` of a fit are cut into overlapping windows; in each
window three statistics are tested against what white N(0, 1) noise gives:

==============  ==============================================================
bias z          ``z = mean(e) sqrt(n)``, N(0, 1) for white noise
scatter         ``s = std(e)`` (the RMS ratio: residual scatter over sigma);
                ``(n - 1) s^2`` is chi2(n - 1)
lag-1 rho       autocorrelation at lag 1 about the window mean; ``rho sqrt(n)``
                is N(0, 1) for white noise
==============  ==============================================================

Thresholds are Bonferroni-corrected over all windows and channels at the
significance ``level`` (``z_crit = Phi^-1(1 - level / (2 m))``, m tests), so
a correct model flags no window in 95 % of data sets at level 0.05.

Beside the windows, the cumulative sum ``C_k = sum_{i<=k} e_i / sqrt(n)``
shows where a drift starts: for white noise it is a random walk inside
``+-2 sqrt(k / n)``; its Brownian bridge ``C_k - (k/n) C_n`` peaks where the
mean of the residuals changes, and ``max |bridge|`` has the Kolmogorov
distribution (``scipy.stats.kstwobign``) under white noise.

Flight conditions (altitude ``h``, speed ``v``, ``mach``, dynamic pressure
``qbar``) are evaluated along the fitted trajectory from the model's own
states and definitions (:func:`rocketid.simulate.evaluate_along`), only
where the model defines them; the attack-angle input ``alpha`` marks the
pitch-over. A model without them gets time windows only. Ascent phases:

==================  ==========================================================
lift-off            from the start until v reaches 50 m/s (or the pitch-over
                    begins, if sooner; without v: the first 5 s)
pitch-over          the first window where the alpha input is non-zero
gravity turn        after the pitch-over, before max-q
max-q               where dynamic pressure is within 10 % of its peak
supersonic climb    after max-q (``climb`` if still subsonic)
==================  ==========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DataError, SettingsError
from ..simulate import evaluate_along
from ..output import new_axes, plot_target, save_figure
from ..solve import EstimationResult
from ..summary import Section, Summary, SummaryText, Table
from .compare import Comparison, compare

__all__ = ["Phase", "WindowTable", "Cusum", "Finding", "Location", "locate", "flight_conditions", "flight_phases",
           "CONDITIONS", "MIN_WINDOW_SAMPLES", "MIN_WINDOWS"]

#: Flight conditions, found through the model's physical roles (:data:`rocketid.model.ROLES`):
#: key -> (label, unit, scale to the unit).
CONDITIONS = {"h": ("altitude", "km", 1e-3), "v": ("speed", "m/s", 1.0), "mach": ("Mach", "", 1.0),
              "qbar": ("q", "kPa", 1e-3)}
#: The role of each condition key (and of the attack angle ``alpha``).
CONDITION_ROLES = {"h": "altitude", "v": "speed", "mach": "mach", "qbar": "dynamic_pressure", "alpha": "attack_angle"}
#: Fewest samples a window may hold, and fewest windows a channel needs.
MIN_WINDOW_SAMPLES = 20
MIN_WINDOWS = 4
LIFTOFF_SPEED = 50.0
MAXQ_FRACTION = 0.9


# ---------------------------------------------------------------------------
# Flight conditions and phases
# ---------------------------------------------------------------------------


def flight_conditions(fit: EstimationResult, times) -> dict[str, np.ndarray]:
    """The flight conditions the model declares, along the fitted trajectory.

    Returns ``{key: values at times}`` for the keys of :data:`CONDITION_ROLES` whose role
    (altitude, speed, Mach, dynamic pressure, attack angle) the model declares; a model
    without a role does not get that condition (:func:`missing_conditions` says which).
    """
    spec = fit.spec
    times = np.asarray(times, float)
    states = fit.states_at(times)
    out = {}
    for key, role in CONDITION_ROLES.items():
        expr = spec.role(role)
        if expr is None:
            continue
        if expr in spec.state_symbols:
            out[key] = states[:, spec.state_symbols.index(expr)].copy()
        elif expr in spec.input_symbols:
            out[key] = spec.input_values(times)[:, spec.input_symbols.index(expr)]
        else:
            with np.errstate(all="ignore"):
                out[key] = evaluate_along(spec, spec.expand(expr), times, states, fit.p)
    return out


def missing_conditions(spec) -> list[str]:
    """The roles of :data:`CONDITION_ROLES` that ``spec`` does not declare."""
    return [role for role in CONDITION_ROLES.values() if spec.role(role) is None]


@dataclass(frozen=True)
class Phase:
    """A flight phase: ``t_start <= t < t_end``."""

    name: str
    t_start: float
    t_end: float
    description: str = ""

    def contains(self, t) -> np.ndarray:
        return (np.asarray(t) >= self.t_start) & (np.asarray(t) < self.t_end)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` indices of the runs of True in ``mask``."""
    idx = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return [(int(a), int(b) - 1) for a, b in zip(idx[::2], idx[1::2])]


def flight_phases(times: np.ndarray, conditions: dict, *, alpha_breakpoints=()) -> tuple[Phase, ...]:
    """Ascent phases from the flight conditions (see the module table); ``()`` when
    the model has neither a speed nor a dynamic pressure (not an ascent model)."""
    t = np.asarray(times, float)
    if t.size < 3 or not ({"v", "qbar", "mach"} & set(conditions)):
        return ()
    t0, tf = float(t[0]), float(t[-1])
    pitch = None
    alpha = conditions.get("alpha")
    if alpha is not None and np.max(np.abs(alpha)) > 0:
        a = np.abs(alpha)
        runs = _runs(a > 0.02 * a.max())
        if runs:
            i, j = runs[0]
            ps, pe = float(t[i]), float(t[j])
            for b in alpha_breakpoints:  # snap to the input's own breakpoints
                if abs(b - ps) <= 1.0:
                    ps = float(b)
                if abs(b - pe) <= 1.0:
                    pe = float(b)
            if pe > ps:
                pitch = (ps, pe)
    if "v" in conditions:
        fast = np.flatnonzero(conditions["v"] >= LIFTOFF_SPEED)
        lo_end = float(t[fast[0]]) if fast.size else tf
    else:
        lo_end = t0 + min(5.0, 0.1 * (tf - t0))
    if pitch is not None and t0 < pitch[0] < lo_end:
        lo_end = pitch[0]
    maxq = None
    if "qbar" in conditions and np.all(np.isfinite(conditions["qbar"])):
        q = conditions["qbar"]
        k = int(np.argmax(q))
        if q[k] > 0:
            i = k
            while i > 0 and q[i - 1] >= MAXQ_FRACTION * q[k]:
                i -= 1
            j = k
            while j < q.size - 1 and q[j + 1] >= MAXQ_FRACTION * q[k]:
                j += 1
            maxq = (float(t[i]), float(t[j]), float(t[k]), float(q[k]))
    phases = [Phase("lift-off", t0, lo_end, f"from the start until v reaches {LIFTOFF_SPEED:g} m/s"
                    if "v" in conditions else "the first seconds")]
    cur = lo_end
    if pitch is not None and pitch[1] > cur:
        start = max(pitch[0], cur)
        if start > cur:
            phases.append(Phase("vertical rise", cur, start, "after lift-off, before the pitch-over"))
        phases.append(Phase("pitch-over", start, pitch[1], "the attack-angle input's first manoeuvre"))
        cur = pitch[1]
    if maxq is not None:
        ms, me = max(maxq[0], cur), maxq[1]
        if ms > cur:
            phases.append(Phase("gravity turn" if pitch is not None else "climb", cur, ms, "before max-q"))
        if me > ms:
            phases.append(Phase("max-q", ms, me, f"dynamic pressure within {100 * (1 - MAXQ_FRACTION):.0f} % of its "
                                                 f"peak ({maxq[3] / 1e3:.0f} kPa at t = {maxq[2]:.0f} s)"))
            cur = me
    if cur < tf:
        rest = (t >= cur)
        supersonic = "mach" in conditions and float(np.median(conditions["mach"][rest])) > 1.0
        name = "supersonic climb" if supersonic else ("gravity turn" if maxq is None and pitch is not None else "climb")
        phases.append(Phase(name, cur, tf + 1e-9, "after max-q" if maxq is not None else ""))
    return tuple(p for p in phases if p.t_end > p.t_start)


# ---------------------------------------------------------------------------
# Windows and cumulative sums
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class WindowTable:
    """Windowed statistics of one channel's normalized residuals (arrays of one
    value per window).

    Attributes
    ----------
    channel : str
    t_start, t_end : ndarray
    n : ndarray of int
    bias : ndarray
        ``mean(e)`` (in sigma).
    z : ndarray
        ``mean(e) sqrt(n)``.
    rms_ratio : ndarray
        ``std(e)``: residual scatter over sigma (1 for a correct model).
    scatter_p : ndarray
        ``P(chi2(n - 1) > (n - 1) std(e)^2)``.
    acf1 : ndarray
        Lag-1 autocorrelation about the window mean.
    biased, scattered, correlated : ndarray of bool
        Which tests flag the window (at the corrected level).
    """

    channel: str
    t_start: np.ndarray
    t_end: np.ndarray
    n: np.ndarray
    bias: np.ndarray
    z: np.ndarray
    rms_ratio: np.ndarray
    scatter_p: np.ndarray
    acf1: np.ndarray
    biased: np.ndarray
    scattered: np.ndarray
    correlated: np.ndarray

    @property
    def flagged(self) -> np.ndarray:
        return self.biased | self.scattered

    @property
    def t_mid(self) -> np.ndarray:
        return 0.5 * (self.t_start + self.t_end)


@dataclass(frozen=True)
class Cusum:
    """The cumulative sum of one channel's normalized residuals.

    Attributes
    ----------
    channel : str
    times : ndarray, shape (n,)
    values : ndarray, shape (n,)
        ``C_k = sum_{i<=k} e_i / sqrt(n)``.
    change_time : float
        Where the bridge ``C_k - (k/n) C_n`` is largest in magnitude: where
        the mean of the residuals changes.
    statistic : float
        ``max |bridge|``.
    p_value : float
        Under white noise (Kolmogorov distribution).
    departure_time : float or None
        First time ``|C_k|`` leaves ``+-3 sqrt(k/n)`` (None if never).
    """

    channel: str
    times: np.ndarray
    values: np.ndarray
    change_time: float
    statistic: float
    p_value: float
    departure_time: float | None


def cusum(channel: str, times: np.ndarray, e: np.ndarray) -> Cusum:
    """The cumulative-sum view of ``e`` (see :class:`Cusum`)."""
    from scipy.stats import kstwobign

    n = e.size
    c = np.cumsum(e) / math.sqrt(n)
    k = np.arange(1, n + 1)
    bridge = c - k / n * c[-1]
    i = int(np.argmax(np.abs(bridge)))
    d = float(abs(bridge[i]))
    out = np.flatnonzero(np.abs(c) > 3 * np.sqrt(k / n) + 3 / math.sqrt(n))
    dep = float(times[out[0]]) if out.size else None
    return Cusum(channel, times, c, float(times[i]), d, float(kstwobign.sf(d)), dep)


# ---------------------------------------------------------------------------
# Findings: failing windows in words
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Finding:
    """A run of failing windows of one channel, described in flight terms.

    Attributes
    ----------
    channel : str
    kind : str
        ``"offset"`` (one sign over most of the flight), ``"drift"`` (a bias
        that grows or shrinks along the run), ``"bias"`` (a bias of steady
        size over part of the flight), or ``"scatter"`` (more scatter than
        sigma without a bias).
    t_start, t_end : float
    sign : int
        Sign of the bias (``model - measured``), 0 for scatter.
    peak_z : float
        Largest ``|z|`` in the run (or the scatter's z-equivalent).
    peak_bias : float
        Bias (in sigma) of the window with the largest ``|z|``.
    rms_ratio : float
        Largest scatter ratio in the run.
    phases : tuple of str
        Phases the run overlaps, in time order.
    conditions : dict
        ``{name: (min, max)}`` over the run, in the units of :data:`CONDITIONS`.
    text : str
        The finding in words.
    """

    channel: str
    kind: str
    t_start: float
    t_end: float
    sign: int
    peak_z: float
    peak_bias: float
    rms_ratio: float
    phases: tuple
    conditions: dict
    text: str

    def to_dict(self) -> dict:
        return {"channel": self.channel, "kind": self.kind, "t_start": self.t_start, "t_end": self.t_end,
                "sign": self.sign, "peak_z": self.peak_z, "peak_bias": self.peak_bias, "rms_ratio": self.rms_ratio,
                "phases": list(self.phases), "conditions": {k: list(v) for k, v in self.conditions.items()},
                "text": self.text}


def _fmt_range(name: str, lo: float, hi: float) -> str:
    label, unit, _ = CONDITIONS[name]
    digits = 1 if name in ("h", "mach") else 0
    a, b = round(lo, digits), round(hi, digits)
    rng = f"{a:.{digits}f}" if a == b else f"{a:.{digits}f}-{b:.{digits}f}"
    return f"{label} {rng}" + (f" {unit}" if unit else "")


def _describe(f_channel, kind, ts, te, sign, peak_bias, peak_z, ratio, phases, conds, span) -> str:
    d = 0 if span >= 20 else (1 if span >= 2 else 2)  # time digits for the flight's length
    where = f"t = {ts:.{d}f}-{te:.{d}f} s"
    if kind == "offset":
        head = (f"{f_channel} residual is offset {'+' if sign > 0 else '-'}{abs(peak_bias):.2g} sigma (model "
                f"{'above' if sign > 0 else 'below'} the data) over {'the whole flight' if te - ts >= 0.9 * span else 'most of the flight'} "
                f"({where})")
    elif kind == "drift":
        head = (f"{f_channel} residual drifts {'positive' if sign > 0 else 'negative'} from t = {ts:.{d}f} s to "
                f"{te:.{d}f} s, up to {peak_bias:+.2g} sigma")
    elif kind == "bias":
        head = f"{f_channel} residual is biased {peak_bias:+.2g} sigma over {where}"
    else:
        head = f"{f_channel} residual scatters {ratio:.2g}x sigma over {where}"
    bits = []
    if phases:
        bits.append(", ".join(phases))
    cond_txt = [_fmt_range(k, *conds[k]) for k in ("mach", "qbar", "h") if k in conds]
    if cond_txt:
        bits.append(", ".join(cond_txt))
    tail = f" ({'; '.join(bits)})" if bits else ""
    return f"{head}{tail}; peak |z| = {abs(peak_z):.0f}"


# ---------------------------------------------------------------------------
# The result
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Location:
    """Where the fit fails: windows, cumulative sums, phases and findings in words.

    Attributes
    ----------
    model : str
    window, step : float
        Window length and step (s).
    level : float
    z_critical : float
        The Bonferroni-corrected threshold of ``|z|`` and of ``rho sqrt(n)``.
    n_tests : int
    condition_times : ndarray
        The grid on which :attr:`conditions` are evaluated.
    conditions : dict
        ``{name: values}`` (SI units; see :data:`CONDITIONS`), from the model.
    phases : tuple of Phase
    windows : dict
        ``{channel: WindowTable}``.
    cusums : dict
        ``{channel: Cusum}``.
    phase_table : tuple of dict
        Per phase and channel: ``phase, channel, n, bias, z, rms_ratio``.
    findings : tuple of Finding
        Most significant first.
    notes : tuple of str
    """

    model: str
    window: float
    step: float
    level: float
    z_critical: float
    n_tests: int
    condition_times: np.ndarray
    conditions: dict
    phases: tuple
    windows: dict
    cusums: dict
    phase_table: tuple
    findings: tuple
    notes: tuple = ()

    @property
    def fails(self) -> bool:
        return bool(self.findings)

    @property
    def earliest(self) -> Finding | None:
        """The finding that starts first (where the model first fails)."""
        return min(self.findings, key=lambda f: (f.t_start, -abs(f.peak_z))) if self.findings else None

    def phase_at(self, t: float) -> str | None:
        for p in self.phases:
            if p.t_start <= t < p.t_end:
                return p.name
        return None

    def sentences(self, limit: int = 6) -> list[str]:
        """The findings in words, most significant first."""
        return [f.text for f in self.findings[:limit]]

    def summary(self) -> SummaryText:
        """Fixed sections (settings, phases, per-phase statistics, findings, cumulative sums) and
        numbered notes: a :class:`~rocketid.summary.Summary`, as its text (:class:`~rocketid.summary.SummaryText`)."""
        sections = [Section("Settings", (
            ("windows", f"{self.window:.3g} s, step {self.step:.3g} s; {self.n_tests} tests; |z| > "
                        f"{self.z_critical:.2f} flags (level {self.level:g}, Bonferroni)"),
            ("conditions", ", ".join(CONDITIONS[k][0] for k in CONDITIONS if k in self.conditions)
             or "none (the model defines no flight condition: time windows only)")))]
        if self.phases:
            end = self.condition_times[-1]
            sections.append(Section("Phases", (Table(
                ("phase", "from (s)", "to (s)", "description"),
                [(p.name, p.t_start, min(p.t_end, end), p.description) for p in self.phases], (None, ".1f", ".1f")),)))
            chans = list(self.windows)
            rows = []
            for p in self.phases:
                row = [p.name]
                for c in chans:
                    r = next((x for x in self.phase_table if x["phase"] == p.name and x["channel"] == c), None)
                    row += [r["z"], r["rms_ratio"]] if r else [float("nan"), float("nan")]
                rows.append(row)
            sections.append(Section("Per phase (bias z = mean(e) sqrt(n); scatter = std(e))", (Table(
                ["phase"] + [h for c in chans for h in (f"{c} z", f"{c} sd")], rows,
                [None] + [f for _ in chans for f in (".1f", ".2f")]),)))
        if self.findings:
            found = [f"- {t}" for t in self.sentences()]
            if len(self.findings) > 6:
                found.append(f"({len(self.findings) - 6} more in to_dict())")
        else:
            found = ["no window fails: the residuals look like white noise everywhere"]
        sections.append(Section("Findings", found))
        sections.append(Section("Cumulative sums (change point of the mean)", (Table(
            ("channel", "change at t (s)", "max |bridge|", "p", "leaves the +-3 band at t (s)"),
            [(c.channel, c.change_time, c.statistic, c.p_value,
              "-" if c.departure_time is None else f"{c.departure_time:.1f}") for c in self.cusums.values()],
            (None, ".1f", ".2f", ".2g")),)))
        return SummaryText(Summary(f"rocketid location: {self.model}", tuple(sections), self.notes))

    def to_dict(self) -> dict:
        return {
            "model": self.model, "window": self.window, "step": self.step, "level": self.level,
            "z_critical": self.z_critical,
            "phases": [{"name": p.name, "t_start": p.t_start, "t_end": p.t_end} for p in self.phases],
            "phase_table": [dict(r) for r in self.phase_table],
            "findings": [f.to_dict() for f in self.findings],
            "cusum": {k: {"change_time": c.change_time, "statistic": c.statistic, "p_value": c.p_value,
                          "departure_time": c.departure_time} for k, c in self.cusums.items()},
            "windows": {k: {"t_start": w.t_start.tolist(), "t_end": w.t_end.tolist(), "z": w.z.tolist(),
                            "rms_ratio": w.rms_ratio.tolist(), "acf1": w.acf1.tolist(),
                            "flagged": w.flagged.tolist()} for k, w in self.windows.items()},
            "notes": list(self.notes),
        }

    # ---- plot
    def plot(self, axes=None, *, path=None, title: str | None = None):
        """Four panels on one time axis, phases shaded: window bias z per channel
        (flagged windows marked), scatter ratio, cumulative sums with their
        +-2 sqrt(k/n) band, and the flight conditions (three panels for a model without them).

        Parameters
        ----------
        axes : sequence of matplotlib Axes, optional
            One per panel (default: a new figure's, outside pyplot: no backend is touched).
        path : str or path, optional
            Save the figure there (``plot("locate.png")`` works too).
        title : str, optional

        Returns
        -------
        ndarray of matplotlib Axes, shape (n_panels,)
        """
        import matplotlib

        axes, path = plot_target(axes, path)
        n_panels = 4 if self.conditions else 3
        own = axes is None
        axes = (new_axes((10, 2.3 * n_panels + 0.5), n_panels, 1, sharex=True) if own
                else np.asarray(axes, dtype=object).ravel())
        if axes.size != n_panels:
            raise SettingsError(f"Location.plot draws {n_panels} panels; it got {axes.size} axes")
        fig = axes[0].figure
        colors = dict(zip(self.windows, matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]))
        shades = ["#f3f3f3", "#e2ecf6"]
        for ax in axes:
            for i, p in enumerate(self.phases):
                ax.axvspan(p.t_start, min(p.t_end, self.condition_times[-1]), color=shades[i % 2], lw=0, zorder=0)
        a = axes[0]
        for ch, w in self.windows.items():
            a.plot(w.t_mid, w.z, "-", color=colors[ch], lw=1.2, label=ch)
            a.plot(w.t_mid[w.biased], w.z[w.biased], "o", color=colors[ch], ms=4)
        a.axhspan(-self.z_critical, self.z_critical, color="tab:green", alpha=0.15, lw=0,
                  label=f"|z| < {self.z_critical:.2f}")
        a.set_yscale("symlog", linthresh=self.z_critical)
        top = max([float(np.max(np.abs(w.z))) for w in self.windows.values()] + [self.z_critical])
        ticks = [0.0] + [s * 10.0 ** k for k in range(1, int(math.ceil(math.log10(max(top, 10.0)))) + 1)
                         for s in (-1, 1)]
        a.set_yticks(sorted(ticks), [f"{t:g}" for t in sorted(ticks)])
        a.minorticks_off()
        a.set_ylabel("window bias z")
        a.legend(loc="upper right", fontsize=7, ncol=4, frameon=False)
        for i, p in enumerate(self.phases):
            a.text(0.5 * (p.t_start + min(p.t_end, self.condition_times[-1])), 1.02, p.name, ha="center", va="bottom",
                   fontsize=7, transform=a.get_xaxis_transform())
        a = axes[1]
        for ch, w in self.windows.items():
            a.plot(w.t_mid, w.rms_ratio, "-", color=colors[ch], lw=1.2, label=ch)
            a.plot(w.t_mid[w.scattered], w.rms_ratio[w.scattered], "o", color=colors[ch], ms=4)
        a.axhline(1.0, color="0.4", lw=0.8)
        a.set_ylabel("scatter std(e)")
        a = axes[2]
        for ch, c in self.cusums.items():
            a.plot(c.times, c.values, "-", color=colors[ch], lw=1.2, label=f"{ch} (change at {c.change_time:.0f} s)")
        tt = np.concatenate([c.times for c in self.cusums.values()])
        tg = np.linspace(tt.min(), tt.max(), 200)
        band = 2 * np.sqrt((tg - tg[0]) / max(tg[-1] - tg[0], 1e-12))
        a.fill_between(tg, -band, band, color="tab:green", alpha=0.15, lw=0, label="+-2 sqrt(k/n)")
        a.set_ylabel("cumulative sum")
        a.legend(loc="upper left", fontsize=7, frameon=False)
        if self.conditions:
            a = axes[3]
            t = self.condition_times
            for name, style in (("h", "-"), ("mach", "--"), ("qbar", ":")):
                if name in self.conditions:
                    label, unit, scale = CONDITIONS[name]
                    vals = self.conditions[name] * scale
                    a.plot(t, vals / max(np.nanmax(np.abs(vals)), 1e-12), style, color="k",
                           label=f"{label} (max {np.nanmax(vals):.3g} {unit})".replace(" )", ")"))
            a.set_ylabel("condition / max")
            a.legend(loc="upper left", fontsize=7, frameon=False)
        axes[-1].set_xlabel("t (s)")
        if own or title:
            fig.suptitle(title or f"{self.model}: where the residuals fail ({len(self.findings)} finding"
                                  f"{'s' if len(self.findings) != 1 else ''})", fontsize=11)
        if own:
            fig.tight_layout()
        if path is not None:
            save_figure(fig, path, dpi=110)
        return axes


# ---------------------------------------------------------------------------
# The entry point
# ---------------------------------------------------------------------------


def _window_grid(t_lo: float, t_hi: float, window: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    n = int(math.floor((t_hi - t_lo - window) / step + 1e-9)) + 1
    starts = t_lo + step * np.arange(max(n, 0))
    ends = starts + window
    if n > 0 and ends[-1] < t_hi - 1e-9:  # the last window ends at the last sample
        starts = np.append(starts, t_hi - window)
        ends = np.append(ends, t_hi)
    return starts, ends


def _acf1(d: np.ndarray) -> float:
    den = float(d @ d)
    return float(d[1:] @ d[:-1] / den) if den > 0 else 0.0


def locate(fit: EstimationResult, comparison: Comparison | None = None, *, window: float | None = None,
           step: float | None = None, level: float = 0.05, n_conditions: int = 661) -> Location:
    """Locate where the fit fails (item 3 of the diagnosis).

    Parameters
    ----------
    fit : EstimationResult
    comparison : Comparison, optional
        From :func:`~rocketid.diagnostics.compare.compare` (made if not given).
    window : float, optional
        Window length in seconds (default: the span / 22, 3 s for a 66 s
        flight, and at least :data:`MIN_WINDOW_SAMPLES` samples).
    step : float, optional
        Window step (default ``window / 2``).
    level : float
        Significance level, Bonferroni-corrected over windows and channels.
    n_conditions : int
        Points of the grid on which flight conditions are evaluated.

    Returns
    -------
    Location

    Raises
    ------
    DataError
        The data are too short for the windows: a channel with fewer than
        :data:`MIN_WINDOWS` windows of :data:`MIN_WINDOW_SAMPLES` samples.
    SettingsError
        A window or step that is not positive, or a level not in (0, 1).
    """
    if not 0 < level < 1:
        raise SettingsError(f"level must be in (0, 1), got {level}")
    comp = comparison if comparison is not None else compare(fit, level=level)
    chans = comp.channels
    t_lo = min(float(c.times[0]) for c in chans)
    t_hi = max(float(c.times[-1]) for c in chans)
    window, step = _window_settings(chans, t_hi - t_lo, window, step)
    windows, zc, n_tests = _window_tables(chans, t_lo, t_hi, window, step, level)
    tg = np.linspace(t_lo, t_hi, max(int(n_conditions), 3))
    conds, phases, notes = _conditions_and_phases(fit, tg)
    cus = {c.name: cusum(c.name, c.times, c.normalized) for c in chans}
    findings = _findings(windows, tg, conds, phases, t_hi - t_lo, zc)
    if findings and not comp.fits_to_noise:
        pass
    elif findings:
        notes.append("some windows fail although the whole-flight statistics pass: a local, short-lived misfit")
    elif not comp.fits_to_noise:
        notes.append("no single window fails, yet the whole-flight statistics do: the misfit is spread thinly over "
                     "the flight (see the cumulative sums)")
    return Location(model=fit.spec.name, window=window, step=step, level=float(level), z_critical=zc,
                    n_tests=int(n_tests), condition_times=tg, conditions=conds, phases=phases, windows=windows,
                    cusums=cus, phase_table=_phase_table(phases, chans), findings=tuple(findings),
                    notes=tuple(notes))


def _window_settings(chans, span: float, window: float | None, step: float | None) -> tuple[float, float]:
    """The window length (default: the span / 22, and at least :data:`MIN_WINDOW_SAMPLES` samples)
    and step (default half the window), checked."""
    dt = max(float(np.median(np.diff(c.times))) if c.n > 1 else span for c in chans)
    if window is None:
        window = max(span / 22.0, MIN_WINDOW_SAMPLES * dt)
    window = float(window)
    if not window > 0:
        raise SettingsError(f"window must be a positive number of seconds, got {window}")
    step = window / 2 if step is None else float(step)
    if not step > 0:
        raise SettingsError(f"step must be a positive number of seconds, got {step}")
    return window, step


def _window_tables(chans, t_lo: float, t_hi: float, window: float, step: float,
                   level: float) -> tuple[dict, float, int]:
    """``({channel: WindowTable}, z_critical, n_tests)``: each channel's windows of at least
    :data:`MIN_WINDOW_SAMPLES` samples tested at the Bonferroni-corrected ``level``."""
    from scipy.stats import chi2, norm

    span = t_hi - t_lo
    starts, ends = _window_grid(t_lo, t_hi, window, step)
    per_channel = []
    for c in chans:
        idx = [(int(np.searchsorted(c.times, a, "left")), int(np.searchsorted(c.times, b, "right")))
               for a, b in zip(starts, ends)]
        good = [(a, b, i) for i, (a, b) in enumerate(idx) if b - a >= MIN_WINDOW_SAMPLES]
        per_channel.append((c, good))
    too_short = [(c.name, len(good)) for c, good in per_channel if len(good) < MIN_WINDOWS]
    if too_short:
        name, k = too_short[0]
        raise DataError(
            f"the data are too short for windowed statistics: channel {name!r} spans {span:.3g} s with "
            f"{next(c.n for c in chans if c.name == name)} samples, which gives {k} window(s) of {window:.3g} s holding "
            f"at least {MIN_WINDOW_SAMPLES} samples; {MIN_WINDOWS} are needed. Pass a shorter window "
            f"(locate(..., window=...)) or use longer data; compare() still works on these data")
    n_tests = sum(len(good) for _, good in per_channel)
    zc = float(norm.isf(level / (2 * n_tests)))
    pc = level / n_tests
    windows = {}
    for c, good in per_channel:
        e = c.normalized
        rows = []
        for a, b, i in good:
            w = e[a:b]
            n = w.size
            m = float(w.mean())
            d = w - m
            s = float(np.sqrt(d @ d / max(n - 1, 1)))
            rows.append((starts[i], ends[i], n, m, m * math.sqrt(n), s, float(chi2.sf((n - 1) * s * s, n - 1)),
                         _acf1(d)))
        arr = np.array(rows, float)
        ts, te, nn, bias, z, rr, sp_, ac = arr.T
        windows[c.name] = WindowTable(c.name, ts, te, nn.astype(int), bias, z, rr, sp_, ac, np.abs(z) > zc,
                                      (sp_ < pc) & (rr > 1), ac * np.sqrt(nn) > zc)
    return windows, zc, n_tests


def _conditions_and_phases(fit: EstimationResult, tg: np.ndarray) -> tuple[dict, tuple, list]:
    """The flight conditions on the grid ``tg`` (those the model's roles give, finite), the ascent
    phases, and notes on what the model's roles leave out."""
    notes = []
    try:
        conds = flight_conditions(fit, tg)
    except Exception as exc:  # a user's model whose definitions cannot be evaluated: time windows only
        conds = {}
        notes.append(f"flight conditions could not be evaluated along the fit ({type(exc).__name__}: {exc}); "
                     "findings name time windows only")
    conds = {k: v for k, v in conds.items() if np.all(np.isfinite(v))}
    alpha_bps = ()
    alpha = fit.spec.role("attack_angle")
    for u in fit.spec.inputs:
        if alpha is not None and u.symbol in alpha.free_symbols:
            alpha_bps = tuple(u.breakpoints)
    phases = flight_phases(tg, conds, alpha_breakpoints=alpha_bps)
    missing = missing_conditions(fit.spec)
    if not any(k in conds for k in ("h", "mach", "qbar")):
        notes.append(f"model {fit.spec.name!r} declares none of the roles altitude, mach, dynamic_pressure: findings "
                     "name time windows only (declare them with m.declare_role)")
    elif missing:
        notes.append(f"model {fit.spec.name!r} declares no {', '.join(missing)} role: the location cannot use "
                     f"{'it' if len(missing) == 1 else 'them'} (declare with m.declare_role)")
    return conds, phases, notes


def _phase_table(phases: tuple, chans) -> tuple:
    """Per phase and channel: ``phase, channel, n, bias, z, rms_ratio`` of the normalized residuals."""
    rows = []
    for p in phases:
        for c in chans:
            sel = p.contains(c.times)
            if sel.sum() >= 2:
                w = c.normalized[sel]
                rows.append({"phase": p.name, "channel": c.name, "n": int(sel.sum()), "bias": float(w.mean()),
                             "z": float(w.mean() * math.sqrt(w.size)), "rms_ratio": float(w.std())})
    return tuple(rows)


def _findings(windows: dict, tg: np.ndarray, conds: dict, phases: tuple, span: float, zc: float) -> list[Finding]:
    out = []
    for ch, w in windows.items():
        sign = np.sign(w.z).astype(int)
        nw = w.z.size
        # a whole-flight offset: one sign in most windows, most of them flagged
        major = 1 if (sign > 0).sum() >= (sign < 0).sum() else -1
        same = (sign == major)
        if same.mean() >= 0.8 and (w.biased & same).mean() >= 0.6:
            # steady size: an offset; growing or changing: a drift over the whole flight
            b = w.bias[w.biased & same]
            steady = float(np.std(b)) <= 0.5 * abs(float(np.mean(b)))
            runs = [(0, nw - 1, major, "offset" if steady else "drift")]
        else:
            runs = []
            for s in (1, -1):
                for a, b in _runs(w.biased & (sign == s)):
                    runs.append((a, b, s, None))
        covered = np.zeros(nw, bool)
        for a, b, s, kind in runs:
            covered[a:b + 1] = True
            seg = slice(a, b + 1)
            # the peak is taken among windows of the finding's own sign, so that the words
            # ("drifts negative") and the number ("up to -2.8e+02 sigma") agree
            own = np.flatnonzero(sign[seg] == s)
            own = own if own.size else np.arange(b + 1 - a)
            k = a + int(own[np.argmax(np.abs(w.z[seg][own]))])
            if kind is None:
                mags = np.abs(w.bias[seg])
                kind = "drift" if b > a and (mags.max() > 2 * max(mags[0], mags[-1], 1e-12) or
                                              mags[-1] > 2 * mags[0] or mags[0] > 2 * mags[-1]) else "bias"
            out.append(_finding(ch, kind, float(w.t_start[a]), float(w.t_end[b]), s, float(w.z[k]),
                                float(w.bias[k]), float(np.max(w.rms_ratio[seg])), tg, conds, phases, span))
        # scatter without a bias
        for a, b in _runs(w.scattered & ~covered):
            seg = slice(a, b + 1)
            k = a + int(np.argmax(w.rms_ratio[seg]))
            n = w.n[k]
            zeq = (w.rms_ratio[k] ** 2 - 1) * math.sqrt((n - 1) / 2)
            out.append(_finding(ch, "scatter", float(w.t_start[a]), float(w.t_end[b]), 0, float(zeq), 0.0,
                                float(w.rms_ratio[k]), tg, conds, phases, span))
    out.sort(key=lambda f: -abs(f.peak_z))
    return out


def _finding(ch, kind, ts, te, sign, z, bias, ratio, tg, conds, phases, span) -> Finding:
    sel = (tg >= ts) & (tg <= te)
    if not sel.any():
        sel = np.abs(tg - 0.5 * (ts + te)) == np.min(np.abs(tg - 0.5 * (ts + te)))
    rng = {}
    for name in ("h", "mach", "qbar"):
        if name in conds:
            vals = conds[name][sel] * CONDITIONS[name][2]
            rng[name] = (float(vals.min()), float(vals.max()))
    ph = tuple(p.name for p in phases if min(p.t_end, te) - max(p.t_start, ts) > 0.25 * min(te - ts, p.t_end - p.t_start))
    text = _describe(ch, kind, ts, te, sign, bias, z, ratio, ph, rng, span)
    return Finding(ch, kind, ts, te, int(sign), float(z), float(bias), float(ratio), ph, rng, text)
