"""The history of a model's revisions: each fit's statistics and the test against the previous one.

:class:`ModelHistory` is an immutable value: :meth:`ModelHistory.add` returns
a new history with one more :class:`Revision`. Each revision records the
model, its number of parameters, the objective ``J``, chi-square per degree
of freedom, the statistic criterion eta (7.10), the RMS residual per channel
and, against the previous revision on the same data, the likelihood-ratio
test (when the new model nests the previous one) and the change of BIC.

eta comes from :func:`rocketid.sampling.criterion.criterion_of` (docs/sampling.md
section 5). eta tests skewness and kurtosis, not whiteness: the table shows
the Ljung-Box p-value of the worst channel beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy import stats

from ..errors import SettingsError
from ..output import new_axes, nulls_for_non_finite, plot_target, save_figure, write_json
from ..solve import EstimationResult
from .refit import DEFAULT_LAGS, information_criteria, ljung_box

__all__ = ["Revision", "ModelHistory", "eta_of"]


def eta_of(fit: EstimationResult) -> float:
    """eta (7.10) of a fit's residuals, each channel divided by its sigma."""
    from ..sampling.criterion import criterion_of
    return float(criterion_of(fit).eta)


@dataclass(frozen=True)
class Revision:
    """One revision of the model.

    Attributes
    ----------
    number : int
        0 for the first.
    label : str
    fit : EstimationResult
    note : str
    eta : float
        Statistic criterion (7.10).
    whiteness : dict
        ``{channel: Ljung-Box p-value}``.
    test : dict or None
        Against the previous revision: ``lr`` and ``p`` (None when the model
        does not nest the previous one), ``dof``, ``delta_bic``, ``note``.
    """

    number: int
    label: str
    fit: EstimationResult
    note: str
    eta: float
    whiteness: dict
    test: dict | None

    @property
    def n_parameters(self) -> int:
        return len(self.fit.spec.parameters)

    @property
    def objective(self) -> float:
        return float(self.fit.objective)

    @property
    def chi2_per_dof(self) -> float:
        return float(self.fit.chi2_per_dof)

    @property
    def rms(self) -> dict:
        return dict(self.fit.rms)

    @property
    def bic(self) -> float:
        return information_criteria(self.fit)[1]

    def to_dict(self) -> dict:
        return {"revision": self.number, "label": self.label, "model": self.fit.spec.name, "note": self.note,
                "n_parameters": self.n_parameters, "n_estimated": int(self.fit.n_estimated),
                "parameters": {k: float(v) for k, v in zip(self.fit.spec.parameter_names, self.fit.p)},
                "objective": self.objective, "chi2_per_dof": self.chi2_per_dof, "eta": float(self.eta),
                "rms": {k: float(v) for k, v in self.rms.items()},
                "whiteness": {k: float(v) for k, v in self.whiteness.items()}, "bic": float(self.bic),
                "converged": bool(self.fit.success),
                "test": None if self.test is None else {k: (None if v is None else (v if isinstance(v, str) else float(v)))
                                                        for k, v in self.test.items()}}


def _same_data(a: EstimationResult, b: EstimationResult) -> bool:
    ma, mb = a.prepared.measurements, b.prepared.measurements
    if ma.names != mb.names:
        return False
    return all(np.array_equal(ma[n].times, mb[n].times) and np.array_equal(ma[n].values, mb[n].values)
               for n in ma.names)


def _test(prev: EstimationResult, new: EstimationResult) -> dict:
    """Likelihood ratio (nested models) and delta BIC of ``new`` against ``prev``."""
    if not _same_data(prev, new):
        return {"lr": None, "p": None, "dof": None, "delta_bic": None,
                "note": "different data from the previous revision: no test"}
    dbic = information_criteria(new)[1] - information_criteria(prev)[1]
    nested = set(prev.spec.parameter_names) <= set(new.spec.parameter_names)
    dof = new.n_estimated - prev.n_estimated
    if not nested or dof <= 0:
        why = "does not contain the previous model's parameters" if not nested else "adds no estimated parameter"
        return {"lr": None, "p": None, "dof": dof, "delta_bic": dbic,
                "note": f"the model {why}: no likelihood-ratio test (compare BIC)"}
    lr = 2.0 * (prev.objective - new.objective)
    p = float(stats.chi2.sf(max(lr, 0.0), dof))
    note = "" if lr >= 0 else "the objective rose: the refit may have stopped in a local minimum"
    return {"lr": lr, "p": p, "dof": dof, "delta_bic": dbic, "note": note}


@dataclass(frozen=True)
class ModelHistory:
    """Revisions of a model, oldest first (immutable: :meth:`add` returns a new history).

    Examples
    --------
    ``history = ModelHistory().add("base", fit).add("+ back-pressure", confirmation.fit)``
    """

    revisions: tuple = ()
    lags: int = DEFAULT_LAGS

    def add(self, label: str, fit: EstimationResult, note: str = "") -> "ModelHistory":
        """A new history with ``fit`` as the next revision."""
        if not isinstance(fit, EstimationResult):
            raise SettingsError(f"a revision needs an EstimationResult, got {type(fit).__name__}")
        test = _test(self.revisions[-1].fit, fit) if self.revisions else None
        white = {ch: ljung_box(r, self.lags)[1] for ch, r in fit.residuals.items()}
        rev = Revision(len(self.revisions), str(label), fit, str(note), eta_of(fit), white, test)
        return ModelHistory(self.revisions + (rev,), self.lags)

    def __len__(self) -> int:
        return len(self.revisions)

    def __getitem__(self, i: int) -> Revision:
        return self.revisions[i]

    @property
    def latest(self) -> Revision:
        if not self.revisions:
            raise SettingsError("the history is empty; add a revision first")
        return self.revisions[-1]

    def table(self) -> str:
        """One row per revision: model, parameters, J, chi2/dof, eta, RMS per channel, worst
        Ljung-Box p, and the test against the previous revision (LR, p, delta BIC)."""
        if not self.revisions:
            return "(empty model history)"
        chans = list(self.revisions[0].fit.rms)
        head = (f"{'rev':>3}  {'model':<26}{'n_p':>4}{'J':>13}{'chi2/dof':>10}{'eta':>9}"
                + "".join(f"{'RMS ' + c:>10}" for c in chans)
                + f"{'white p':>9}{'LR':>12}{'p':>10}{'dBIC':>12}")
        lines = [head, "-" * len(head)]
        notes = []
        for r in self.revisions:
            t = r.test or {}
            lr = "-" if t.get("lr") is None else f"{t['lr']:.5g}"
            p = "-" if t.get("p") is None else ("<1e-300" if t["p"] == 0 else
                                                 f"{t['p']:.3g}" if t["p"] >= 1e-3 else f"{t['p']:.1e}")
            db = "-" if t.get("delta_bic") is None else f"{t['delta_bic']:+.5g}"
            wp = min(r.whiteness.values())
            label = r.label if len(r.label) <= 25 else r.label[:24] + "~"
            lines.append(f"{r.number:>3}  {label:<26}{r.n_parameters:>4}{r.objective:>13.6g}{r.chi2_per_dof:>10.4g}"
                         f"{r.eta:>9.3g}" + "".join(f"{r.rms.get(c, math.nan):>10.4g}" for c in chans)
                         + f"{(f'{wp:.2g}' if wp >= 1e-99 else '<1e-99'):>9}{lr:>12}{p:>10}{db:>12}")
            if r.note:
                notes.append(f"revision {r.number} ({r.label}): {r.note}")
            if t.get("note"):
                notes.append(f"revision {r.number}: {t['note']}")
            if not r.fit.success:
                notes.append(f"revision {r.number}: the fit did not converge ({r.fit.message})")
        lines.append(f"(LR, p, dBIC: against the previous revision; white p: smallest Ljung-Box p over the channels, "
                     f"{self.lags} lags)")
        if notes:
            lines.append("Notes")
            lines += [f"  [{i}] {n}" for i, n in enumerate(notes, 1)]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"revisions": [r.to_dict() for r in self.revisions], "lags": self.lags}

    def to_json(self, path) -> Path:
        return write_json(path, nulls_for_non_finite(self.to_dict()))

    def plot_residuals(self, axes=None, *, path=None, revisions: Sequence[int] | None = None, window: float = 1.0):
        """Residuals against time, one panel per channel, before (first revision) and after
        (last), or the given revisions: the samples lightly, their ``window``-second moving
        average boldly.

        Parameters
        ----------
        axes : sequence of matplotlib Axes, optional
            One per channel (default: a new figure's, outside pyplot: no backend is touched).
        path : str or path, optional
            Save the figure there (``plot_residuals("history.png")`` works too).

        Returns
        -------
        ndarray of matplotlib Axes, shape (n_channels,)
        """
        import matplotlib

        axes, path = plot_target(axes, path)
        if not self.revisions:
            raise SettingsError("the history is empty; add a revision first")
        if revisions is None:
            revisions = [0, len(self.revisions) - 1] if len(self.revisions) > 1 else [0]
        try:
            chosen = [self.revisions[i] for i in revisions]
        except IndexError:
            raise SettingsError(f"revisions must index 0..{len(self.revisions) - 1}, got {list(revisions)}") from None
        chans = list(chosen[0].fit.residuals)
        own = axes is None
        axes = (new_axes((10, 2.6 * len(chans)), len(chans), 1, sharex=True, squeeze=False) if own
                else np.asarray(axes, dtype=object)).ravel()
        if axes.size != len(chans):
            raise SettingsError(f"plot_residuals draws one panel per channel ({len(chans)}); it got {axes.size} axes")
        colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
        for ax, ch in zip(axes, chans):
            for k, r in enumerate(chosen):
                t = r.fit.prepared.measurements[ch].times
                e = r.fit.residuals[ch]
                col = colors[k % len(colors)]
                ax.plot(t, e, ",", color=col, alpha=0.35)
                dt = np.median(np.diff(t)) if t.size > 1 else 1.0
                n = max(1, int(round(window / dt)))
                if e.size >= n:
                    avg = np.convolve(e, np.ones(n) / n, mode="valid")
                    ax.plot(t[n // 2:n // 2 + avg.size], avg, color=col, lw=1.8,
                            label=f"{r.number}: {r.label} (RMS {r.rms[ch]:.3g})")
            ax.axhline(0.0, color="k", lw=0.6)
            ax.set_ylabel(f"{ch} residual")
            ax.legend(loc="upper left", fontsize=8)
        axes[-1].set_xlabel("t, s")
        fig = axes[0].figure
        if own:
            fig.suptitle("residuals (model - measurement): samples and " + f"{window:g} s moving average")
            fig.tight_layout()
        if path is not None:
            save_figure(fig, path, dpi=110)
        return axes
