"""Confirming a candidate effect by refitting: likelihood ratio, AIC/BIC, whiteness, RMS, hold-out.

The score test (:mod:`rocketid.diagnostics.score`) ranks candidates at the
base fit; :func:`confirm` adds one (or a confounded group of them) and
refits from the model's nominal aerodynamic values -- the guesses declared
in the model, not the base estimate, which the missing effect has distorted.
It reports, base against new:

* the likelihood-ratio statistic ``LR = 2 (J_base - J_new) ~ chi2(dof)``,
  ``dof`` the number of added parameters;
* ``AIC = 2 J + 2 k`` and ``BIC = 2 J + k ln(n)`` (``k`` estimated
  quantities, ``n`` data; the constant of the Gaussian likelihood dropped);
* the Ljung-Box whiteness test per channel (:func:`ljung_box`);
* the RMS residual per channel;
* a hold-out check: both models fitted on the early window (default
  0-45 s) and their predictions of the rest of the flight compared with the
  measurements (simulated with the high-accuracy integrator);
* the effect's estimates with standard errors and 95 % intervals
  (:func:`rocketid.estimability.uncertainty`);
* the discretization check: the refit's collocation predictions against a
  high-accuracy simulation at the same estimate (an effect acting at
  lift-off needs a short first element, ``docs/effects.md``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from ..data import Channel, Measurements
from ..errors import DataError, RocketidError, SensitivityError, SettingsError
from ..estimability import uncertainty
from ..nlp import ParameterTransform
from ..sensitivity import sensitivity_at
from ..simulate import simulate
from ..solve import EstimationResult, estimate, prepare
from .effects import Effect, resolve_effects, with_effects

__all__ = ["Confirmation", "confirm", "ljung_box", "information_criteria", "DEFAULT_LAGS"]

DEFAULT_LAGS = 20
"""Lags of the Ljung-Box test (0.2 s at 100 Hz)."""

WEAK = 0.25
"""Standard error, as a share of the realistic size (or of the estimate), above which a note calls an
effect parameter weakly identifiable."""

BLIND = 1e-6
"""Sensitivity-column norm (times the nominal value), relative to the largest, at or below which the
hold-out window's data do not reach a parameter."""

DISCRETIZATION_WARN = 0.1
"""Collocation-minus-simulation difference, in noise sigmas, above which a note asks for a finer mesh."""


def ljung_box(residuals: Sequence[float], lags: int = DEFAULT_LAGS) -> tuple[float, float]:
    """The Ljung-Box portmanteau test of whiteness.

    ``Q = n (n + 2) sum_{k=1..h} rho_k^2 / (n - k)`` with ``rho_k`` the sample
    autocorrelation at lag ``k``; under white residuals ``Q ~ chi2(h)``.

    Parameters
    ----------
    residuals : sequence of float, shape (n,)
        In time order.
    lags : int
        ``h``.

    Returns
    -------
    (Q, p_value)
    """
    e = np.asarray(residuals, float).ravel()
    n = e.size
    if not isinstance(lags, (int, np.integer)) or lags < 1:
        raise SettingsError(f"lags must be a positive integer, got {lags!r}")
    if n <= lags + 1:
        raise DataError(f"the Ljung-Box test with {lags} lags needs more than {lags + 1} residuals, got {n}")
    d = e - e.mean()
    c0 = float(np.einsum("i,i->", d, d))
    if c0 == 0.0:
        return 0.0, 1.0
    k = np.arange(1, lags + 1)
    rho = np.array([np.einsum("i,i->", d[j:], d[:-j]) for j in k]) / c0
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - k)))
    return q, float(stats.chi2.sf(q, lags))


def information_criteria(fit: EstimationResult) -> tuple[float, float]:
    """``(AIC, BIC) = (2 J + 2 k, 2 J + k ln n)`` of a fit (Gaussian constant dropped)."""
    k, n = fit.n_estimated, fit.n_data
    return 2 * fit.objective + 2 * k, 2 * fit.objective + k * math.log(n)


@dataclass(frozen=True)
class Confirmation:
    """The base model against the model with the effect, refitted.

    Attributes
    ----------
    effects : tuple of str
        The effect(s) added.
    fit : EstimationResult
        The refit with the effect (from nominal values).
    base_fit : EstimationResult
    lr_statistic, lr_p_value : float
        ``2 (J_base - J_new)`` and ``P(chi2(dof) > LR)``.
    dof : int
        Added estimated quantities.
    aic, bic : (float, float)
        (base, new).
    whiteness : dict
        ``{channel: (p before, p after)}`` of the Ljung-Box test.
    rms : dict
        ``{channel: (before, after)}``.
    holdout_rms : dict or None
        ``{channel: (base, new)}``: RMS of the prediction of the samples after
        the hold-out window by the models fitted on the window.
    effect_estimates : dict
        ``{parameter: (estimate, standard error, (low, high))}``, 95 % interval.
    chi2_per_dof : (float, float)
        (base, new).
    discretization : dict
        ``{channel: max |collocation - simulation| / sigma}`` at the refit.
    holdout : (float, float) or None
    level : float
    lags : int
    notes : tuple of str
    timings : dict
    holdout_fits : tuple or None
        (base, new) fits on the hold-out window.
    effect_covariance : ndarray or None
        Covariance of the effect's parameters (in ``effect_estimates`` order).
    """

    effects: tuple
    fit: EstimationResult
    base_fit: EstimationResult
    lr_statistic: float
    lr_p_value: float
    dof: int
    aic: tuple
    bic: tuple
    whiteness: dict
    rms: dict
    holdout_rms: dict | None
    effect_estimates: dict
    chi2_per_dof: tuple
    discretization: dict
    holdout: tuple | None
    level: float
    lags: int
    notes: tuple = ()
    timings: dict = field(default_factory=dict)
    holdout_fits: tuple | None = field(default=None, repr=False)
    effect_covariance: np.ndarray | None = field(default=None, repr=False)

    @property
    def confirmed(self) -> bool:
        """LR significant at the level, BIC lower and the refit converged."""
        return bool(self.fit.success and self.lr_p_value < self.level and self.bic[1] < self.bic[0])

    def covers(self, truth: Mapping[str, float]) -> dict[str, bool]:
        """Whether each 95 % interval covers a known true value (for studies with synthetic data)."""
        return {k: bool(self.effect_estimates[k][2][0] <= float(v) <= self.effect_estimates[k][2][1])
                for k, v in truth.items()}

    def joint_coverage(self, truth: Mapping[str, float]) -> tuple[float, float]:
        """``(d^T C^-1 d, p)`` for ``d`` the estimates minus ``truth`` of all the effect's parameters
        and ``C`` their covariance: the truth lies in the joint 95 % region when ``p > 0.05``
        (the check for a multi-parameter effect, whose separate intervals are correlated)."""
        names = list(self.effect_estimates)
        if self.effect_covariance is None or set(truth) != set(names):
            raise SettingsError(f"give a true value for each of {', '.join(names)}")
        d = np.array([self.effect_estimates[n][0] - float(truth[n]) for n in names])
        m = float(d @ np.linalg.solve(self.effect_covariance, d))
        return m, float(stats.chi2.sf(m, len(names)))

    def to_dict(self) -> dict:
        def pair(t):
            return [None if v is None else float(v) for v in t]
        return {
            "effects": list(self.effects), "confirmed": self.confirmed,
            "lr_statistic": float(self.lr_statistic), "lr_p_value": float(self.lr_p_value), "dof": int(self.dof),
            "aic": pair(self.aic), "bic": pair(self.bic), "chi2_per_dof": pair(self.chi2_per_dof),
            "whiteness": {k: pair(v) for k, v in self.whiteness.items()},
            "rms": {k: pair(v) for k, v in self.rms.items()},
            "holdout": list(self.holdout) if self.holdout else None,
            "holdout_rms": {k: pair(v) for k, v in self.holdout_rms.items()} if self.holdout_rms else None,
            "effect_estimates": {k: {"estimate": float(v), "std_err": float(s), "interval_95": [float(a), float(b)]}
                                 for k, (v, s, (a, b)) in self.effect_estimates.items()},
            "discretization": {k: float(v) for k, v in self.discretization.items()},
            "parameters": {k: float(v) for k, v in zip(self.fit.spec.parameter_names, self.fit.p)},
            "level": self.level, "lags": self.lags, "notes": list(self.notes),
            "timings": {k: float(v) for k, v in self.timings.items()},
        }

    def summary(self) -> str:
        """Fixed sections: test, fit per channel, hold-out, effect estimates; then numbered notes."""
        verdict = "CONFIRMED" if self.confirmed else "not confirmed"
        lines = [f"rocketid confirmation: {self.base_fit.spec.name} + {' + '.join(self.effects)} ({verdict})",
                 "=" * 72,
                 "Test against the base model",
                 f"  LR statistic  : {self.lr_statistic:.6g} on {self.dof} dof, p = {_p(self.lr_p_value)}",
                 f"  AIC           : {self.aic[0]:.6g} -> {self.aic[1]:.6g}",
                 f"  BIC           : {self.bic[0]:.6g} -> {self.bic[1]:.6g}  (delta {self.bic[1] - self.bic[0]:+.4g})",
                 f"  chi2 / dof    : {self.chi2_per_dof[0]:.4g} -> {self.chi2_per_dof[1]:.4g}",
                 "Channels (before -> after)",
                 f"  {'channel':<9}{'RMS':>24}{f'Ljung-Box p ({self.lags} lags)':>30}"]
        for ch in self.rms:
            a, b = self.rms[ch]
            wa, wb = self.whiteness[ch]
            lines.append(f"  {ch:<9}{a:>11.4g} -> {b:<10.4g}{_p(wa):>17} -> {_p(wb):<10}")
        if self.holdout_rms:
            lines.append(f"Hold-out (fit {self.holdout[0]:g}-{self.holdout[1]:g} s, predict the rest): prediction RMS, "
                         "base -> new")
            for ch, (a, b) in self.holdout_rms.items():
                lines.append(f"  {ch:<9}{a:>11.4g} -> {b:<10.4g}")
        lines.append("Effect parameters (95 % interval)")
        for name, (v, s, (lo, hi)) in self.effect_estimates.items():
            lines.append(f"  {name:<14}{v:>13.6g} +- {s:<10.3g} [{lo:.6g}, {hi:.6g}]")
        if self.notes:
            lines.append("Notes")
            lines += [f"  [{i}] {n}" for i, n in enumerate(self.notes, 1)]
        return "\n".join(lines)


def _p(p: float) -> str:
    if p is None or not np.isfinite(p):
        return "-"
    if p == 0.0:
        return "<1e-300"
    return f"{p:.3g}" if p >= 1e-3 else f"{p:.1e}"


def _predict(fit: EstimationResult, measurements: Measurements) -> dict[str, np.ndarray]:
    """Outputs of ``fit``'s model at its estimate, at each channel's sample times (high-accuracy simulation)."""
    times = np.unique(np.concatenate([c.times for c in measurements.channels]))
    traj = simulate(fit.spec, fit.p, times, rtol=1e-10, atol=1e-10)
    if not traj.success:
        raise RocketidError(f"the prediction failed: {traj.message}")
    out = traj.outputs()
    return {c.name: np.interp(c.times, times, out[c.name]) for c in measurements.channels}


def _after(measurements: Measurements, t_split: float) -> Measurements | None:
    chans = []
    for c in measurements.channels:
        keep = c.times > t_split
        if not keep.any():
            return None
        chans.append(Channel(c.name, c.times[keep], c.values[keep], c.sigma))
    return Measurements(tuple(chans))


def _fit_window(spec, window: Measurements, mesh, guess, options, reference: np.ndarray):
    """Fit ``spec`` to the hold-out window from its nominal guesses, holding at their guesses the
    parameters the window's data do not reach (zero sensitivity at ``reference``, e.g. a drag
    knot at a Mach number the vehicle reaches only later)."""
    prep = prepare(spec, window, mesh=mesh)
    p0 = spec.parameter_vector(guess)
    blind: list[str] = []
    try:
        sens = sensitivity_at(prep, reference)
        S = sens.S / sens.sigma[:, None] * spec.nominal[None, :]
        cn = np.sqrt(np.einsum("ij,ij->j", S, S))
        mask = cn <= BLIND * cn.max()
        blind = [n for n, b in zip(spec.parameter_names, mask) if b]
        if mask.any() and not mask.all():
            tf = ParameterTransform(np.eye(mask.size)[:, ~mask], np.where(mask, p0, 0.0),
                                    tuple(n for n, b in zip(spec.parameter_names, mask) if not b))
            prep = replace(prep, nlp=prep.nlp.with_transform(tf))
    except SensitivityError:
        pass
    return estimate(spec, window, guess=guess, mesh=mesh, options=options, prepared=prep), blind


def confirm(fit: EstimationResult, effect: Effect | str | Sequence[Effect | str], *,
            holdout: tuple[float, float] | None = (0.0, 45.0), guess: Mapping | None = None,
            level: float = 0.05, lags: int = DEFAULT_LAGS, options: Mapping[str, Any] | None = None) -> Confirmation:
    """Add ``effect`` to ``fit``'s model, refit from nominal values and compare (module notes).

    Parameters
    ----------
    fit : EstimationResult
        The base fit.
    effect : Effect, str, or a sequence of them
        One effect, or a confounded group to add together.
    holdout : (float, float) or None
        Fit window of the hold-out check (samples after it are predicted);
        None skips the check.
    guess : mapping, optional
        Starting values by parameter name over the model's nominal guesses
        (effect parameters start at 0).
    level : float
        Level of the likelihood-ratio test.
    lags : int
        Lags of the Ljung-Box test.
    options : mapping, optional
        IPOPT options.

    Returns
    -------
    Confirmation

    Raises
    ------
    ModelError
        The effect is already present or does not apply.
    """
    if not (0.0 < float(level) < 1.0):
        raise SettingsError(f"level must be in (0, 1), got {level!r}")
    t0 = time.perf_counter()
    effects = resolve_effects(effect)
    base_spec = fit.spec
    spec = with_effects(base_spec, effects)
    data = fit.prepared.measurements
    mesh = fit.prepared.transcription.mesh
    new = estimate(spec, data, guess=guess, mesh=mesh, options=options)
    t1 = time.perf_counter()
    notes: list[str] = []
    if not new.success:
        notes.append(f"the refit did not converge ({new.message}); its statistics are not those of an optimum")
    dof = new.n_estimated - fit.n_estimated
    lr = 2.0 * (fit.objective - new.objective)
    if lr < 0:
        notes.append(f"the refit ended above the base objective (J {new.objective:.6g} > {fit.objective:.6g}): a "
                     "local minimum; try another guess")
        lr_p = 1.0
    else:
        lr_p = float(stats.chi2.sf(lr, dof)) if dof > 0 else float("nan")
    aic0, bic0 = information_criteria(fit)
    aic1, bic1 = information_criteria(new)
    white, rms = {}, {}
    for ch in fit.nlp.channel_names:
        white[ch] = (ljung_box(fit.residuals[ch], lags)[1], ljung_box(new.residuals[ch], lags)[1])
        rms[ch] = (fit.rms[ch], new.rms[ch])

    # the effect's parameters with their uncertainty
    declared = [n for n in spec.parameter_names if n not in set(base_spec.parameter_names)]
    estimates = {}
    cov = None
    try:
        unc = uncertainty(new)
        iv = unc.interval(0.95)
        for n in declared:
            i = spec.parameter_names.index(n)
            estimates[n] = (float(new.p[i]), float(unc.standard_errors[i]), (float(iv[i, 0]), float(iv[i, 1])))
        idx = [spec.parameter_names.index(n) for n in declared]
        cov = unc.parameter_covariance[np.ix_(idx, idx)]
        for note in unc.notes:
            notes.append(f"uncertainty: {note}")
        realistic = {k: v for e in effects for k, v in e.realistic.items()}
        for n in declared:
            v, se, _ = estimates[n]
            i = spec.parameter_names.index(n)
            corr = np.nan_to_num(unc.correlations[i].copy())
            corr[i] = 0.0
            j = int(np.argmax(np.abs(corr)))
            scale = abs(realistic.get(n, 0.0)) or abs(v)
            if scale > 0 and se > WEAK * scale:
                notes.append(f"{n} is only weakly identifiable from these data: its standard error {se:.3g} is "
                             f"{100 * se / scale:.0f} % of its {'realistic size' if n in realistic else 'estimate'}"
                             f" (largest correlation {corr[j]:+.3f}, with {spec.parameter_names[j]})")
    except SensitivityError as exc:
        for n in declared:
            i = spec.parameter_names.index(n)
            estimates[n] = (float(new.p[i]), float("nan"), (float("nan"), float("nan")))
        notes.append(f"no uncertainty for the effect's parameters: {exc}")
    for e in effects:
        for n, mag in e.realistic.items():
            if n in estimates and mag and abs(estimates[n][0]) > 10 * abs(mag):
                notes.append(f"{n} = {estimates[n][0]:.4g} is more than 10 times its realistic magnitude "
                             f"{mag:g}: implausible; the effect may be standing in for another one")

    # discretization: the collocation against the high-accuracy simulator at the refit's estimate
    disc = {}
    try:
        pred = _predict(new, data)
        sig = dict(zip(new.nlp.channel_names, new.nlp.channel_sigmas))
        worst = []
        for ch in new.nlp.channel_names:
            d = np.abs(new.predictions[ch] - pred[ch]) / sig[ch]
            disc[ch] = float(d.max())
            worst.append((disc[ch], ch, float(data[ch].times[int(np.argmax(d))])))
        w = max(worst)
        if w[0] > DISCRETIZATION_WARN:
            notes.append(f"the collocation differs from the high-accuracy simulation by up to {w[0]:.2g} sigma ({w[1]} "
                         f"at t = {w[2]:.3g} s): refine the mesh (default_mesh(spec, refine_first=3) shortens the "
                         "first element, which effects acting at lift-off need)")
    except RocketidError as exc:
        notes.append(f"the discretization check failed: {exc}")
    t2 = time.perf_counter()

    # hold-out: fit both models on the window, predict the rest
    hold_rms, hold_fits = None, None
    if holdout is not None:
        a, b = (float(holdout[0]), float(holdout[1]))
        if not b > a:
            raise SettingsError(f"holdout must be a window (start, end) with end > start, got {holdout!r}")
        rest = _after(data, b)
        if rest is None:
            notes.append(f"no samples after t = {b:g} s: the hold-out check was skipped")
        else:
            try:
                window = data.window(a, b)
                fb, blind_b = _fit_window(base_spec, window, mesh, None, options, fit.p)
                fn, blind_n = _fit_window(spec, window, mesh, guess, options, new.p)
                hold_fits = (fb, fn)
                pb, pn = _predict(fb, rest), _predict(fn, rest)
                hold_rms = {c.name: (float(np.sqrt(np.mean((pb[c.name] - c.values) ** 2))),
                                     float(np.sqrt(np.mean((pn[c.name] - c.values) ** 2)))) for c in rest.channels}
                for label, f, blind in (("base", fb, blind_b), ("new", fn, blind_n)):
                    if not f.success:
                        notes.append(f"the {label} model's hold-out fit did not converge ({f.message})")
                    if blind:
                        notes.append(f"the data of the hold-out window do not reach {', '.join(blind)} of the {label} "
                                     "model: held at their guesses in its hold-out fit and prediction")
            except RocketidError as exc:
                notes.append(f"the hold-out check failed: {exc}")
    t3 = time.perf_counter()
    return Confirmation(
        effects=tuple(e.name for e in effects), fit=new, base_fit=fit, lr_statistic=float(lr),
        lr_p_value=float(lr_p), dof=int(dof), aic=(aic0, aic1), bic=(bic0, bic1), whiteness=white, rms=rms,
        holdout_rms=hold_rms, effect_estimates=estimates, chi2_per_dof=(fit.chi2_per_dof, new.chi2_per_dof),
        discretization=disc, holdout=None if holdout is None else (float(holdout[0]), float(holdout[1])),
        level=float(level), lags=int(lags), notes=tuple(notes),
        timings={"refit_s": t1 - t0, "checks_s": t2 - t1, "holdout_s": t3 - t2, "total_s": t3 - t0},
        holdout_fits=hold_fits, effect_covariance=cov)
