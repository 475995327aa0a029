"""Step 3 of the discovery -- accept: does a refit explain the data?

::

    screen -> refit -> accept -> step -> report

A likelihood-ratio test only says that an effect *helps*; a confident wrong
answer comes from taking the best helper for the explanation. An effect is
**accepted** (it explains the data) when its refit

1. **converged** (IPOPT, within its time limit);
2. is **significant**: the LR test ``2 (J_before - J_after) ~ chi2(dof)`` below
   the level divided by the number of contenders refitted (Bonferroni), and BIC
   fell;
3. **reaches the noise**: chi2/dof inside the :class:`NoiseBand`, computed from
   the degrees of freedom (the 99.9 % point of chi2(dof)/dof) plus the
   discretization error measured on clean data -- the collocation against the
   high-accuracy simulation of the fitted model itself;
4. leaves residuals **no less white than clean data would**: the Ljung-Box p of
   every channel, Holm-corrected over the channels, above :data:`WHITE_LEVEL`
   (at 100 Hz a correct model's residuals pass it; a single channel's uncorrected
   p = 0.012 does not fail a clean fit);
5. is **determined** and keeps the **base coefficients plausible**: its standard errors exist and none
   exceeds :data:`UNDETERMINED_FACTOR` realistic sizes (a
   refit whose reduced Hessian is singular has estimates that are one point of a set that fits as
   well -- on a sounding rocket whose drag rises at burn-out, a 7-knot density profile reached the
   noise that way), a located shape's location is placed (each event time's or hump's standard error
   within the step of the scan that located it: the same rocket's drag rise was explained by 9.9 kg
   released at 2.3 +- 3.1 s), the plausibility checks pass, and when the fit
   before it was already inside the noise band, no coefficient moves by more than
   :data:`SHIFT_LIMIT` unless chi2/dof falls by at least :data:`SHIFT_GAIN` of its standard
   deviation -- a small improvement bought by redrawing the drag table is not an explanation);
6. has a **plausible size**: every added parameter within :data:`SIZE_FACTOR` times
   its realistic size *for this vehicle* (a fraction of its thrust, mass flow,
   speed; :meth:`~rocketid.diagnostics.effects.Effect.sizes`), not below the least
   its physics allows (:attr:`~rocketid.diagnostics.effects.Effect.least`: Earth's
   rotation), not held at a bound, and no change between neighbouring parameters of a
   profile beyond :data:`SIZE_FACTOR` times its realistic size
   (:attr:`~rocketid.diagnostics.effects.Effect.changes`: a wind's shear between knots; a
   profile that alternates +-100 m/s from knot to knot fits anything and is no wind), and no
   mean that its physics makes positive below zero by more than :data:`SIGN_SIGMAS` standard
   errors (:attr:`~rocketid.diagnostics.effects.Effect.positive`: a power-off base drag averaged
   over the Mach range flown; a warm nitrous tank on Wren-H was called explained by a base drag of
   -0.25 to -0.03 -- less drag once the jet stops -- beside a burn-rate error).

A refit that passes 1, 2 and 6 is **admissible**: it is a step toward the
explanation (the stepwise search adds it and looks for the rest: while another
effect is still missing, chi2/dof, whiteness and the coefficients may all still
be off) but it is never called explained or confirmed; the final model must pass
every check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy import stats

from ..solve import EstimationResult
from .refit import Refit

__all__ = ["Check", "Acceptance", "NoiseBand", "noise_band", "accept", "whiteness_ok", "fits_to_noise",
           "WHITE_LEVEL", "SIZE_FACTOR", "FINDING_FACTOR", "BAND_LEVEL", "SIGN_SIGMAS", "UNDETERMINED_FACTOR"]

WHITE_LEVEL = 0.001
"""Holm-corrected Ljung-Box p (over the channels) below which residuals are not white."""

SIZE_FACTOR = 5.0
"""An added parameter beyond this many realistic sizes is implausible."""

FINDING_FACTOR = 10.0
"""An effect that explains the data at more than :data:`SIZE_FACTOR` times its realistic size, but at most this,
is a finding when nothing plausible explains them (:attr:`Acceptance.oversized`): a stated number off by that
much (a thrust 12 % off, 6 times the realistic 2 %). Beyond it the shape stands in for something else -- the
studies' refits that reached the noise at 12-300 times their sizes were density profiles of -176 % and winds
of 2800 m/s."""

UNDETERMINED_FACTOR = 1000.0
"""An added parameter whose standard error exceeds this many realistic sizes is not determined by the data, as one
without a standard error is (the reduced Hessian singular to rounding): Tern-2 with a back-pressure on a cold day
was called explained by a 7-knot density profile whose knots were -0.17 to 0.19 +- 620-890 (realistic 0.05). No
explained model in the documented studies' tables has a standard error of 100 or more."""

SIGN_SIGMAS = 2.0
"""A mean that an effect's physics makes positive (:attr:`~rocketid.diagnostics.effects.Effect.positive`) is the
wrong sign below ``-SIGN_SIGMAS`` times its standard error bound. (Measured on Wren-H: a true base drag's Mach
average 0.11 +- 0.02; the warm tank's wrong one -0.11 +- 0.02; and on Petrel-V a 10 K colder day's base drag that
stood in for the density, -0.0069 +- 0.0021.)"""

BAND_LEVEL = 0.001
"""Upper tail of chi2(dof)/dof that bounds the noise band."""

DISCRETIZATION_LIMIT = 0.1
"""Largest discretization error, in chi2/dof, that the noise band allows for: more is a mesh too coarse
for the flight (or a fit that is not a trajectory), not the discretization of a usable mesh (the default
meshes leave 1e-5 to 1e-2)."""

SHIFT_LIMIT = 0.2
"""When the fit before the refit is already inside the noise band, an effect that moves a base
coefficient by more than this share while chi2/dof falls by less than :data:`SHIFT_GAIN` of its
standard deviation ``sqrt(2/dof)`` is standing in for a change of the coefficients."""

SHIFT_GAIN = 0.5
"""See :data:`SHIFT_LIMIT`. (A missing effect that the coefficients absorbed moves them back by
much, and buys a clear fall of chi2/dof: RA-66M with a hidden back-pressure, 1.0151 -> 1.0065 with
sqrt(2/dof) = 0.010; a density profile tied with it moved the drag table 25-85 % for 0.0015.)"""


@dataclass(frozen=True)
class NoiseBand:
    """chi2/dof that a correct model reaches on these data.

    Attributes
    ----------
    upper : float
        ``chi2.isf(BAND_LEVEL, dof) / dof + D / dof``.
    dof : int
    discretization : float
        ``D = sum((collocation - simulation)^2 / sigma^2)`` at the base fit: what the
        discretization alone adds to ``2 J`` on clean data (NaN when it could not be measured).
    note : str
    """

    upper: float
    dof: int
    discretization: float
    note: str = ""

    def contains(self, chi2_per_dof: float) -> bool:
        return bool(np.isfinite(chi2_per_dof) and chi2_per_dof <= self.upper)

    def to_dict(self) -> dict:
        return {"upper": float(self.upper), "dof": int(self.dof), "discretization": float(self.discretization),
                "note": self.note}


def difference_variance_factor(order: int) -> float:
    """``sum_l rho_l^2`` over the lags of the ``order``-th differences of white noise (``rho_l =
    C(2k, k + l) / C(2k, k)``): how much the overlap of the differences inflates the variance of a mean of
    their squares (2.63 for k = 4)."""
    k = int(order)
    return float(sum((math.comb(2 * k, k + l) / math.comb(2 * k, k)) ** 2 for l in range(-k, k + 1)))


def noise_band(fit: EstimationResult, *, timeout: float = 60.0,
               estimated: Mapping[str, int] | None = None) -> NoiseBand:
    """The noise band of ``fit``'s data, with the discretization error measured by simulating the
    fitted model at its estimate with the high-accuracy integrator (under a time limit).

    ``estimated``: ``{channel: number of differences}`` for channels whose sigma was estimated from the
    data alone (:func:`rocketid.data.difference_noise`). Their sigmas are uncertain, and chi2/dof with
    them scatters more than with known ones: the band is widened by the variance their estimates add,
    ``sum_c (n_c / N)^2 2 F / m_c`` (``n_c`` the channel's samples, ``m_c`` its differences, ``F``
    :func:`difference_variance_factor`), at the band's tail probability."""
    from ..data import DIFFERENCE_ORDER
    from ..simulate import simulate

    dof = max(1, fit.n_data - fit.n_estimated)
    base = float(stats.chi2.isf(BAND_LEVEL, dof) / dof)
    widened = ""
    if estimated:
        counts = {c.name: c.values.size for c in fit.prepared.measurements.channels}
        n_all = max(1, sum(counts.values()))
        F = difference_variance_factor(DIFFERENCE_ORDER)
        v_est = sum((counts.get(c, 0) / n_all) ** 2 * 2.0 * F / max(1, m) for c, m in estimated.items())
        z = float(stats.norm.isf(BAND_LEVEL))
        base += z * (math.sqrt(2.0 / dof + v_est) - math.sqrt(2.0 / dof))
        widened = (f"widened for the noise of {', '.join(estimated)} estimated from the data (its uncertainty adds "
                   f"{math.sqrt(v_est):.2g} to chi2/dof's standard deviation)")
    meas = fit.prepared.measurements
    times = np.unique(np.concatenate([c.times for c in meas.channels]))
    note = ""
    D = math.nan
    if not fit.success:
        # the last iterate of a fit that did not converge is not a trajectory of its parameters: its distance
        # from the simulation measures that, not the discretization (measured: Stage-30 with a misalignment
        # from the start, base fit locally infeasible: a 'band' up to chi2/dof 4.4e6)
        return NoiseBand(base, dof, D, "the fit did not converge: the discretization error is not measured; "
                                       "the band holds none")
    try:
        traj = simulate(fit.spec, fit.p, times, rtol=1e-10, atol=1e-10, max_wall_time=timeout)
        if traj.success:
            out = traj.outputs()
            sig = dict(zip(fit.nlp.channel_names, fit.nlp.channel_sigmas))
            D = float(sum(np.sum(((fit.predictions[c.name] - np.interp(c.times, times, out[c.name])) / sig[c.name]) ** 2)
                          for c in meas.channels))
        else:
            note = f"the discretization error could not be measured ({traj.message}); the band holds none"
    except Exception as exc:  # noqa: BLE001 - the band stays usable without it
        note = f"the discretization error could not be measured ({exc}); the band holds none"
    extra = D / dof if np.isfinite(D) else 0.0
    if extra > DISCRETIZATION_LIMIT:
        note = (f"the collocation differs from the simulation of the fitted model by {extra:.3g} in chi2/dof, more "
                f"than a discretization error (<= {DISCRETIZATION_LIMIT:g}): a finer mesh is needed; the band holds none")
        extra = 0.0
    note = "; ".join(x for x in (note, widened) if x)
    return NoiseBand(base + extra, dof, D, note)


def holm_min(p: Sequence[float]) -> float:
    """The smallest Holm-adjusted p-value of a family (= min over i of (m - i) p_(i), capped at 1)."""
    p = np.sort(np.asarray([x for x in p if np.isfinite(x)], float))
    if p.size == 0:
        return math.nan
    return float(min(1.0, np.min((p.size - np.arange(p.size)) * p)))


def whiteness_ok(pvalues: Mapping[str, float]) -> tuple[bool, str]:
    """Residuals no less white than clean data would leave: Holm over channels at :data:`WHITE_LEVEL`."""
    adj = holm_min(list(pvalues.values()))
    if not np.isfinite(adj):
        return False, "no whiteness test"
    worst = min(pvalues, key=lambda k: pvalues[k] if np.isfinite(pvalues[k]) else -1)
    ok = adj >= WHITE_LEVEL
    return ok, (f"Ljung-Box p, Holm-corrected over {len(pvalues)} channels: {adj:.2g} "
                f"({'>=' if ok else '<'} {WHITE_LEVEL:g}; lowest channel {worst}, p = {pvalues[worst]:.2g})")


def fits_to_noise(fit: EstimationResult, band: NoiseBand) -> tuple[bool, str]:
    """A fit reaches the noise: chi2/dof inside the band and residuals white (module notes)."""
    from .refit import ljung_box
    white = {ch: float(ljung_box(r)[1]) for ch, r in fit.residuals.items()}
    ok_w, why_w = whiteness_ok(white)
    ok_c = band.contains(fit.chi2_per_dof)
    return ok_w and ok_c, (f"chi2/dof {fit.chi2_per_dof:.4g} {'inside' if ok_c else 'above'} the noise band "
                           f"(<= {band.upper:.4g}); {why_w}")


@dataclass(frozen=True)
class Check:
    """One criterion of the acceptance test."""

    name: str
    passed: bool
    detail: str

    def to_dict(self) -> dict:
        return {"passed": bool(self.passed), "detail": self.detail}


#: The checks an admissible step needs (a step toward the explanation). The coefficients are not
#: among them: while another effect is still missing it distorts them; the final model must pass.
ADMISSIBLE = ("converged", "significant", "size")
#: The checks of an explanation: every one.
ALL = ("converged", "significant", "noise", "white", "coefficients", "size")


@dataclass(frozen=True)
class Acceptance:
    """The acceptance test of one refit.

    Attributes
    ----------
    refit : Refit
    checks : tuple of Check
        In the order of :data:`ALL`.
    level : float
        The family-wise level of the LR test it was judged at.
    n_tests : int
        The Bonferroni count it was judged with (the contenders of its step).
    """

    refit: Refit
    checks: tuple
    level: float = 0.05
    n_tests: int = 1

    def check(self, name: str) -> Check:
        return next(c for c in self.checks if c.name == name)

    @property
    def accepted(self) -> bool:
        """Every check passed: the effect explains the data."""
        return all(c.passed for c in self.checks)

    @property
    def admissible(self) -> bool:
        """Converged, significant and a plausible size: a step toward the explanation (the
        coefficients may still be distorted by another missing effect)."""
        return all(self.check(n).passed for n in ADMISSIBLE)

    @property
    def oversized(self) -> bool:
        """Passes every check of an explanation but the size, and fails that only by magnitude: an estimate
        beyond :data:`SIZE_FACTOR` times its realistic size but none beyond :data:`FINDING_FACTOR`, none held at
        a bound, below its physics' least or changing too steeply between knots. It explains the data at a size the vehicle's stated numbers
        make implausible (a thrust 12 % off its stated value) -- a finding, not an explanation."""
        r = self.refit
        if self.failed != ["size"] or not r.success or r.at_bound:
            return False
        if any(abs(r.estimate(k)[0]) < m for k, m in r.least.items()):
            return False
        if any(_beyond(r.estimate(k), m) for k, m in r.most.items()):
            return False
        if any(v > SIZE_FACTOR for v in r.change_ratio().values()) or r.wrong_signs():
            return False
        ratios = r.size_ratio().values()
        return any(v > SIZE_FACTOR for v in ratios) and all(v <= FINDING_FACTOR for v in ratios)

    @property
    def failed(self) -> list[str]:
        return [c.name for c in self.checks if not c.passed]

    def reason(self) -> str:
        """Why it is not accepted (empty when it is)."""
        return "; ".join(f"{c.name}: {c.detail}" for c in self.checks if not c.passed)

    def to_dict(self) -> dict:
        return {"accepted": self.accepted, "admissible": self.admissible,
                "checks": {c.name: c.to_dict() for c in self.checks}}


def _beyond(estimate: tuple, most: float) -> bool:
    """An estimate ``(value, std)`` beyond ``most`` in magnitude by more than :data:`SIGN_SIGMAS` standard errors (by
    its value alone when it has none)."""
    value, std = estimate
    return abs(value) - (SIGN_SIGMAS * std if np.isfinite(std) else 0.0) > most


def _mean_words(weights: Mapping[str, float]) -> str:
    """A weighted mean in words: the parameter itself, or "the (weighted) mean of first..last"."""
    if len(weights) == 1:
        return next(iter(weights))
    names = list(weights)
    even = np.allclose(list(weights.values()), 1.0 / len(weights))
    return f"{'the mean' if even else 'the weighted mean'} of {names[0]}..{names[-1]}"


def accept(refit: Refit, band: NoiseBand, *, level: float = 0.05, n_tests: int = 1) -> Acceptance:
    """The acceptance test of ``refit`` (module notes).

    Parameters
    ----------
    refit : Refit
    band : NoiseBand
        The noise band of the data.
    level : float
        Family-wise level of the LR tests.
    n_tests : int
        Number of contenders refitted at this step (Bonferroni).
    """
    checks = []
    if refit.gave_up:
        checks.append(Check("converged", False, refit.message))
    elif not refit.success:
        checks.append(Check("converged", False, f"the refit did not converge ({refit.message})"))
    else:
        checks.append(Check("converged", True, f"converged in {refit.seconds:.1f} s"))
    lr, p = refit.lr_statistic, refit.lr_p_value
    b0, b1 = refit.bic if refit.success else (math.nan, math.nan)
    alpha = level / max(1, int(n_tests))
    sig = bool(np.isfinite(p) and p < alpha and b1 < b0)
    checks.append(Check("significant", sig, f"LR {lr:.4g} on {refit.dof} dof, p = {p:.2g} "
                                            f"({'<' if np.isfinite(p) and p < alpha else '>='} {alpha:.2g}); "
                                            f"BIC {b0:.6g} -> {b1:.6g}"))
    inside = band.contains(refit.chi2_per_dof)
    checks.append(Check("noise", inside, f"chi2/dof {refit.chi2_per_dof:.4g} {'inside' if inside else 'above'} the "
                                         f"noise band (<= {band.upper:.4g})"))
    ok_w, why_w = whiteness_ok(refit.whiteness) if refit.whiteness else (False, "no residuals")
    checks.append(Check("white", ok_w, why_w))
    moved, shift = refit.coefficient_shift() if refit.success else ("", 0.0)
    settled = band.contains(refit.base_chi2_per_dof)
    gain = refit.base_chi2_per_dof - refit.chi2_per_dof
    small_gain = not gain >= SHIFT_GAIN * math.sqrt(2.0 / max(1, band.dof))
    loose = [n for n in refit.effect_parameters if refit.success and refit.sizes.get(n)
             and refit.estimate(n)[1] > UNDETERMINED_FACTOR * refit.sizes[n]]
    if refit.success and not all(np.isfinite(refit.estimate(n)[1]) for n in refit.effect_parameters):
        why = next((n for n in refit.notes if n.startswith("no standard errors")), "no standard errors")
        checks.append(Check("coefficients", False, f"not determined by these data ({why}): the estimates are one "
                                                   "point of a set that fits as well, not a measurement"))
    elif loose:
        checks.append(Check("coefficients", False, "not determined by these data: " + "; ".join(
            f"{n} = {refit.estimate(n)[0]:.4g} +- {refit.estimate(n)[1]:.3g}, a standard error "
            f"{refit.estimate(n)[1] / refit.sizes[n]:.3g} times its realistic size" for n in loose[:3])
            + ": the estimates are one point of a set that fits as well, not a measurement"))
    elif unplaced := [n for n, step in refit.location_steps.items() if refit.success
                      and not refit.estimate(n)[1] <= step]:
        checks.append(Check("coefficients", False, "; ".join(
            f"{n} = {refit.estimate(n)[0]:.4g} +- {refit.estimate(n)[1]:.2g} is not placed by these data (its "
            f"standard error exceeds the {refit.location_steps[n]:.3g} step of the scan that located it): what "
            "explains the data is not an event there" for n in unplaced)))
    elif refit.plausible_coefficients is False:
        checks.append(Check("coefficients", False, "; ".join(refit.implausible[:3])))
    elif settled and shift > SHIFT_LIMIT and small_gain:
        checks.append(Check("coefficients", False, f"{moved} moves by {100 * shift:.0f} % from a fit that was already "
                                                   f"inside the noise band (chi2/dof {refit.base_chi2_per_dof:.4g}) for "
                                                   f"a gain of only {gain:.2g} in chi2/dof: the effect stands in for a "
                                                   "change of the coefficients"))
    else:
        checks.append(Check("coefficients", True, "not checked" if refit.plausible_coefficients is None else
                            f"plausible (largest change {moved or '-'} {100 * shift:.0f} %)"))
    ratios = refit.size_ratio() if refit.success else {}
    big = {k: r for k, r in ratios.items() if r > SIZE_FACTOR}
    steep = {ab: r for ab, r in (refit.change_ratio() if refit.success else {}).items() if r > SIZE_FACTOR}
    small = {k: m for k, m in refit.least.items() if refit.success and abs(refit.estimate(k)[0]) < m}
    # beyond the most its physics allows by more than SIGN_SIGMAS standard errors: a knot the data do not pin (a
    # profile's top knot above the air the flight feels) is not judged by its estimate alone (Petrel-V's fleet: a
    # 5-knot wind's top knot at 124.8 m/s refused a right path)
    huge = {k: m for k, m in refit.most.items() if refit.success and _beyond(refit.estimate(k), m)}
    bound = list(refit.at_bound)
    wrong = refit.wrong_signs() if refit.success else []
    if big or bound or small or steep or wrong or huge:
        bits = [f"{k} = {refit.estimate(k)[0]:.4g} is {r:.1f} times its realistic size {refit.sizes[k]:.3g}"
                for k, r in big.items()]
        bits += [f"{b} - {a} = {refit.estimate(b)[0] - refit.estimate(a)[0]:+.4g} is {r:.1f} times the realistic change "
                 f"{refit.changes[(a, b)]:.3g} between them" for (a, b), r in steep.items()]
        bits += [f"{k} = {refit.estimate(k)[0]:.3g} is below {m:g}, the least its physics allows" for k, m in small.items()]
        bits += [f"{k} = {refit.estimate(k)[0]:.4g} is beyond {m:g}, the most its physics allows" for k, m in huge.items()]
        bits += [f"{k} is held at a bound" for k in bound]
        bits += [f"{_mean_words(g)} = {m:.3g} +- {se:.2g} is below zero: the wrong sign for its physics"
                 for g, m, se in wrong]
        checks.append(Check("size", False, "; ".join(bits)))
    else:
        worst = max(ratios.items(), key=lambda kv: kv[1]) if ratios else None
        checks.append(Check("size", True, "no realistic size stated" if worst is None else
                            f"largest {worst[0]}: {worst[1]:.2g} of its realistic size"))
    return Acceptance(refit, tuple(checks), float(level), max(1, int(n_tests)))
