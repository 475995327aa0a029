"""Plausibility of the estimated coefficients: where a fit that looks fine is not.

Flexible coefficients absorb a missing effect: with the chapter's time-knot
drag CD(t) the residuals can stay near the noise while the coefficients take
values no vehicle has (``docs/time-knot-trap.md``). These checks read the
estimates, their standard errors (:func:`rocketid.estimability.uncertainty`)
and the fitted trajectory, and flag:

==================  ==========================================================
``at-bound``        an estimate at (within ``1e-5`` of the span of) a bound:
                    the data push it further, the bound holds it
``wrong-sign``      a drag coefficient or lift slope below zero
``implausible``     a drag coefficient outside ``drag_range`` by more than two
                    standard errors; an effect parameter more than
                    ``effect_factor`` times its realistic size
``undetermined``    a standard error larger than the estimate itself
``mach-smooth``     a time-knot drag CD(t_k) that no smooth function of the
                    Mach number M(t_k) at those times explains (below)
``subsonic-flat``   time-knot drag that varies by more than
                    ``subsonic_spread`` (relative) between knots below Mach 0.8,
                    where a slender body's drag is nearly constant
``supersonic-rise`` the drag coefficient flown (the model's drag role along the
                    fitted trajectory, whatever its parameterization and the
                    effects added to it) rising with the Mach number above
                    Mach 1.5 by more than ``supersonic_tolerance`` plus two
                    standard errors (below), within each piece of the flight
                    where the Mach number climbs or falls (a coast after
                    burn-out is judged apart from the burn: the drag with the
                    motor off may differ at the same Mach number)
==================  ==========================================================

The supersonic check. Past the transonic peak (Mach 1.0-1.3 for a launch
vehicle or a finned rocket) every part of the drag coefficient falls with the
Mach number: wave drag as ``1 / sqrt(M^2 - 1)``, base drag and skin friction
too; tabulated rocket drag curves (Stage-30's, RA-66M's, missile DATCOM
estimates) decline monotonically from Mach 1.5 on. A fitted drag that climbs
there is standing in for something else -- measured: a late thrust shortfall of
a solid motor, fitted as a drag correction in Mach plus a wind, drew a CD
rising from 0.48 at Mach 2.5 to 0.75 at Mach 3 and reached the noise. The
check evaluates the drag coefficient and the Mach number at the fit's
collocation nodes where Mach >= :data:`SUPERSONIC_MACH`, takes the largest rise
``CD(M_b) - min over M_a < M_b of CD(M_a)`` and its standard error (the
gradient of the drag coefficient in the parameters, with the states held, and
the parameter covariance), and flags a rise above ``supersonic_tolerance``
(default 0.05, the Mach-consistency test's tolerance) plus two standard
errors. It needs the ``drag_coefficient`` and ``mach`` roles and at least
:data:`SUPERSONIC_SPAN` of Mach flown above 1.5.

The Mach-consistency test. For a drag family piecewise linear in time on
knots ``t_k`` (``CD0..CD6``), the Mach number ``M_k`` at each knot time comes
from the fitted trajectory. The knot values are fitted by generalized least
squares with a smooth drag curve: a polynomial of degree ``d`` in ``M``
(default 2) plus a transonic drag-rise term of free height,
``exp(-((M - 1.1) / 0.25)^2 / 2)`` (what a launch vehicle's CD(M) looks like:
flat subsonic, a rise near Mach 1, a supersonic decline), with the
covariance ``C + tau^2 I``: ``C`` the knots' covariance from the reduced
Hessian (:func:`rocketid.estimability.uncertainty`), ``tau`` (default 0.05)
the tolerance of the check. The misfit ``chi2 = r^T (C + tau^2 I)^-1 r`` is
tested against chi2(n_knots - d - 2).

Why a tolerance: the knots' standard errors are of order 1e-3 with 6600
samples per channel, and a knot of a function piecewise linear in time is not
a sample of CD(M) at the knot's Mach number; against the standard errors alone
every real drag curve fails. Measured on RA-66M's data without a hidden
effect, fitted with six time segments (``docs/time-knot-trap.md``): p = 0.1
with tau = 0.05 (p = 1e-3 with tau = 0.03); a quadratic without the
transonic term gives p = 0.03 there, and flags a pure transonic drag rise on
RA-66's vehicle (p = 0.009) that the default family accepts (p = 0.9).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..errors import RocketidError, SettingsError
from ..simulate import evaluate_along
from ..output import new_axes, plot_target, save_figure
from ..solve import EstimationResult
from ..summary import Section, Summary, SummaryText, Table

__all__ = ["Flag", "MachConsistency", "Plausibility", "check_plausibility", "coefficient_kinds", "COEFFICIENT_RULES",
           "SEVERITIES"]

#: Severity of a flag, most severe first.
SEVERITIES = ("fail", "warn", "info")

#: ``(glob pattern of parameter names, kind)``; the first match wins. The fallback for a model
#: without the ``drag_coefficient`` / ``lift_coefficient`` roles (:func:`coefficient_kinds`):
#: with the roles, a parameter's kind is what it enters, whatever its name.
COEFFICIENT_RULES = (("dCD*", "effect"), ("CD*", "drag"), ("CL_alpha*", "lift slope"), ("CL*", "lift"))

#: The kinds each coefficient role gives (and that its name rules give without the role).
_ROLE_KINDS = {"drag_coefficient": ("drag",), "lift_coefficient": ("lift slope", "lift")}


@dataclass(frozen=True)
class Flag:
    """One finding about the coefficients.

    Attributes
    ----------
    code : str
        ``at-bound``, ``wrong-sign``, ``implausible``, ``undetermined``,
        ``mach-smooth``, ``subsonic-flat`` or ``supersonic-rise``.
    severity : str
        ``fail`` (physically impossible or held by a bound), ``warn``, ``info``.
    parameters : tuple of str
    message : str
    """

    code: str
    severity: str
    parameters: tuple
    message: str

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity, "parameters": list(self.parameters),
                "message": self.message}


@dataclass(frozen=True)
class MachConsistency:
    """The test of a time-knot drag family against a smooth function of Mach.

    Attributes
    ----------
    family : str
    knots : tuple of str
        Knot parameter names.
    times, mach, values, standard_errors : ndarray, shape (n_k,)
        Knot times, Mach number there (fitted trajectory), estimates, standard errors.
    smooth : ndarray, shape (n_k,)
        The fitted smooth drag curve at the knots.
    coefficients : ndarray
        Of the basis ``M^d .. M, 1`` then, with ``transonic``, the drag-rise term.
    standardized : ndarray, shape (n_k,)
        ``(value - smooth) / sqrt(se^2 + tau^2)``.
    statistic : float
        ``r^T (C + tau^2 I)^-1 r``.
    dof : int
    p_value : float
    degree : int
    tolerance : float
        ``tau``.
    transonic : bool
        Whether the smooth family has the transonic drag-rise term.
    """

    family: str
    knots: tuple
    times: np.ndarray
    mach: np.ndarray
    values: np.ndarray
    standard_errors: np.ndarray
    smooth: np.ndarray
    coefficients: np.ndarray
    standardized: np.ndarray
    statistic: float
    dof: int
    p_value: float
    degree: int
    tolerance: float
    transonic: bool = True

    @property
    def family_name(self) -> str:
        return (f"degree-{self.degree} polynomial in Mach" + (" + transonic rise" if self.transonic else ""))

    def curve(self, mach) -> np.ndarray:
        """The fitted smooth drag curve at Mach numbers ``mach``."""
        return _basis(np.asarray(mach, float), self.degree, self.transonic) @ self.coefficients

    def to_dict(self) -> dict:
        return {"family": self.family, "knots": list(self.knots), "times": self.times.tolist(),
                "mach": self.mach.tolist(), "values": self.values.tolist(),
                "standard_errors": self.standard_errors.tolist(), "smooth": self.smooth.tolist(),
                "standardized": self.standardized.tolist(), "statistic": self.statistic, "dof": self.dof,
                "p_value": self.p_value, "degree": self.degree, "tolerance": self.tolerance,
                "transonic": self.transonic}


@dataclass(frozen=True)
class Plausibility:
    """The plausibility checks of one fit.

    Attributes
    ----------
    model : str
    names : tuple of str
    estimates, standard_errors, lower, upper : ndarray, shape (n_p,)
    kinds : tuple of str
        Each parameter's kind (``drag``, ``lift slope``, ``lift``, ``effect``, ``other``).
    flags : tuple of Flag
        Most severe first.
    mach_checks : tuple of MachConsistency
    level : float
    notes : tuple of str
    """

    model: str
    names: tuple
    estimates: np.ndarray
    standard_errors: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    kinds: tuple
    flags: tuple
    mach_checks: tuple
    level: float
    notes: tuple = ()

    @property
    def passed(self) -> bool:
        """No ``fail`` or ``warn`` flag."""
        return not any(f.severity in ("fail", "warn") for f in self.flags)

    def flagged(self, code: str | None = None, severity: str | None = None) -> tuple:
        """Flags with this code and/or severity."""
        return tuple(f for f in self.flags if (code is None or f.code == code)
                     and (severity is None or f.severity == severity))

    def flagged_parameters(self, severity: tuple = ("fail", "warn")) -> tuple:
        """Names of the parameters that carry a flag of these severities."""
        out = []
        for f in self.flags:
            if f.severity in severity:
                out += [p for p in f.parameters if p not in out]
        return tuple(out)

    def coefficient_table(self) -> Table:
        """One row per parameter: kind, estimate, standard error, bounds, the codes of its flags."""
        return Table(("name", "kind", "estimate", "std err", "lower", "upper", "flags"),
                     [(n, self.kinds[i], self.estimates[i], self.standard_errors[i], self.lower[i], self.upper[i],
                       ", ".join(sorted({f.code for f in self.flags if n in f.parameters})))
                      for i, n in enumerate(self.names)],
                     (None, None, ".5g", ".3g", ".3g", ".3g"))

    def table(self) -> str:
        """:meth:`coefficient_table` as text."""
        return "\n".join("  " + line for line in self.coefficient_table().text_lines())

    def summary(self) -> SummaryText:
        """Fixed sections (verdict, coefficients, Mach consistency, flags) and numbered notes: a
        :class:`~rocketid.summary.Summary`, as its text (:class:`~rocketid.summary.SummaryText`)."""
        n_fail = len(self.flagged(severity="fail"))
        n_warn = len(self.flagged(severity="warn"))
        sections = [Section("", (("verdict", f"{'plausible' if self.passed else 'IMPLAUSIBLE'} ({n_fail} fail, "
                                             f"{n_warn} warn, {len(self.flags) - n_fail - n_warn} info)"),)),
                    Section("Coefficients", (self.coefficient_table(),))]
        for mc in self.mach_checks:
            sections.append(Section(
                f"Time-knot {mc.family}(t) against a smooth drag curve ({mc.family_name}; tolerance {mc.tolerance:g})",
                (Table(("knot", "t (s)", "Mach", "value", "smooth", "std resid"),
                       list(zip(mc.knots, mc.times, mc.mach, mc.values, mc.smooth, mc.standardized)),
                       (None, ".1f", ".2f", ".4f", ".4f", ".2f")),
                 f"misfit chi2 = {mc.statistic:.3g} on {mc.dof} dof, p = {mc.p_value:.2g}")))
        if self.flags:
            sections.append(Section("Flags", [f"[{i}] {f.severity.upper()} {f.code}: {f.message}"
                                              for i, f in enumerate(self.flags, 1)]))
        return SummaryText(Summary(f"rocketid plausibility: {self.model}", tuple(sections), self.notes))

    def to_dict(self) -> dict:
        return {"model": self.model, "passed": self.passed,
                "parameters": [{"name": n, "kind": k, "estimate": float(v), "standard_error": float(s),
                                "lower": float(lo), "upper": float(hi)}
                               for n, k, v, s, lo, hi in zip(self.names, self.kinds, self.estimates,
                                                             self.standard_errors, self.lower, self.upper)],
                "flags": [f.to_dict() for f in self.flags], "mach_checks": [m.to_dict() for m in self.mach_checks],
                "notes": list(self.notes)}

    def plot(self, axes=None, *, path=None):
        """For each time-knot drag family: the knots against Mach with +-2 sqrt(se^2 + tau^2)
        bars and the smooth fit (left), and against time (right). Without such a family:
        each coefficient with its bounds and 2-sigma bar, flagged ones in red.

        Parameters
        ----------
        axes : matplotlib Axes, or array of them, shape (n_families, 2), optional
            Default: a new figure's, outside pyplot (no backend is touched).
        path : str or path, optional
            Save the figure there (``plot("plausibility.png")`` works too).

        Returns
        -------
        ndarray of matplotlib Axes, shape (n_families, 2), or one Axes without a time-knot drag family
        """
        axes, path = plot_target(axes, path)
        own = axes is None
        if self.mach_checks:
            n = len(self.mach_checks)
            axes = new_axes((10, 3.4 * n), n, 2, squeeze=False) if own else np.asarray(axes, dtype=object)
            if axes.size != 2 * n:
                raise SettingsError(f"Plausibility.plot draws {n} rows of 2 panels; it got {axes.size} axes")
            axes = axes.reshape(n, 2)
            fig = axes[0, 0].figure
            self._plot_mach_checks(axes)
            if own:
                fig.suptitle(f"{self.model}: is the time-knot drag a smooth function of Mach?", fontsize=11)
        else:
            axes = new_axes((max(5.0, 0.7 * len(self.names) + 2), 3.4)) if own else axes
            fig = axes.figure
            self._plot_estimates(axes)
        if own:
            fig.tight_layout()
        if path is not None:
            save_figure(fig, path, dpi=110)
        return axes

    def _plot_mach_checks(self, axes) -> None:
        flagged = set(self.flagged_parameters())
        for (a1, a2), mc in zip(axes, self.mach_checks):
            bar = 2 * np.sqrt(np.nan_to_num(mc.standard_errors, nan=0.0) ** 2 + mc.tolerance ** 2)
            col = ["tab:red" if k in flagged else "tab:blue" for k in mc.knots]
            mm = np.linspace(min(mc.mach.min(), 0), mc.mach.max() * 1.05, 200)
            a1.plot(mm, mc.curve(mm), "-", color="0.3", label=f"{mc.family_name} (p = {mc.p_value:.2g})")
            a1.errorbar(mc.mach, mc.values, yerr=bar, fmt="none", ecolor="0.5", capsize=3)
            a1.scatter(mc.mach, mc.values, c=col, zorder=3, s=28)
            for k, m_, v in zip(mc.knots, mc.mach, mc.values):
                a1.annotate(k, (m_, v), textcoords="offset points", xytext=(4, 4), fontsize=7)
            a1.set_xlabel("Mach number at the knot time")
            a1.set_ylabel(f"{mc.family} knot value")
            a1.legend(fontsize=7, loc="best")
            a2.plot(mc.times, mc.values, "o-", color="tab:blue")
            a2.scatter(mc.times, mc.values, c=col, zorder=3, s=28)
            i = self.names.index(mc.knots[0])
            a2.axhline(self.lower[i], color="tab:red", ls=":", lw=0.8, label="bounds")
            a2.axhline(self.upper[i], color="tab:red", ls=":", lw=0.8)
            a2.set_xlabel("knot time (s)")
            a2.set_ylabel(f"{mc.family}(t)")
            a2.legend(fontsize=7)

    def _plot_estimates(self, ax) -> None:
        flagged = set(self.flagged_parameters())
        x = np.arange(len(self.names))
        span = np.where(np.isfinite(self.upper - self.lower), self.upper - self.lower, np.abs(self.estimates) + 1)
        rel = (self.estimates - np.where(np.isfinite(self.lower), self.lower, self.estimates - span / 2)) / span
        err = 2 * np.nan_to_num(self.standard_errors) / span
        col = ["tab:red" if n in flagged else "tab:blue" for n in self.names]
        ax.errorbar(x, rel, yerr=err, fmt="none", ecolor="0.5", capsize=3)
        ax.scatter(x, rel, c=col, zorder=3)
        ax.axhline(0, color="tab:red", ls=":", lw=0.8)
        ax.axhline(1, color="tab:red", ls=":", lw=0.8)
        ax.set_xticks(x, self.names, rotation=30, fontsize=8)
        ax.set_ylabel("position between bounds")
        ax.set_title(f"{self.model}: estimates between their bounds (red: flagged)", fontsize=10)


def _kind(name: str) -> str:
    """A parameter's kind by its name (:data:`COEFFICIENT_RULES`)."""
    for pattern, kind in COEFFICIENT_RULES:
        if fnmatch.fnmatchcase(name, pattern):
            return kind
    return "other"


def _role_parameters(spec, role: str) -> list:
    """The parameter symbols the role's expression depends on (a time family by its knots), in
    declaration order."""
    used = spec.expand(spec.role(role)).free_symbols
    fams = {k for f in spec.families if f.symbol in used for k in f.knots}
    return [ps.symbol for ps in spec.parameters if ps.symbol in used or ps.symbol in fams]


def coefficient_kinds(spec) -> tuple[dict, tuple]:
    """Each parameter's kind (``drag``, ``lift slope``, ``lift``, ``effect``, ``other``) by the
    model's roles, and notes on what fell back to names.

    A parameter the ``drag_coefficient`` role's expression depends on is ``drag`` (an effect's
    correction named ``dCD*`` stays ``effect``); one the ``lift_coefficient`` role depends on is
    a ``lift slope`` when its term moves with the ``attack_angle`` role, else ``lift``. A model
    without a role gets that role's kinds by the name patterns of :data:`COEFFICIENT_RULES`
    (``CD*`` drag, ``CL_alpha*`` lift slope, ``CL*`` lift), and a note says so.

    Returns
    -------
    ({name: kind}, notes)
    """
    names = spec.parameter_names
    by_name = {n: _kind(n) for n in names}
    kinds = {n: "effect" if k == "effect" else "other" for n, k in by_name.items()}
    alpha = spec.role("attack_angle")
    alpha_syms = spec.expand(alpha).free_symbols if alpha is not None else set()
    missing = []
    for role, role_kinds in _ROLE_KINDS.items():
        if spec.role(role) is None:
            missing.append(role)
            kinds.update({n: k for n, k in by_name.items() if k in role_kinds})
            continue
        expr = spec.expand(spec.role(role))
        for sym in _role_parameters(spec, role):
            n = str(sym)
            if kinds[n] in ("effect", "drag"):
                continue
            if role == "drag_coefficient":
                kinds[n] = "drag"
            else:
                fam = next((f.symbol for f in spec.families if sym in f.knots), sym)
                slope = alpha_syms and (sp.diff(expr, fam).free_symbols & alpha_syms)
                kinds[n] = "lift slope" if slope else "lift"
    notes = ()
    if missing:
        notes = (f"model {spec.name!r} declares no {' or '.join(repr(r) for r in missing)} role: its coefficients "
                 "are recognized by name (CD* drag, CL_alpha* lift slope, CL* lift); declare the role "
                 "(m.declare_role) to have them checked whatever their names",)
    return kinds, notes


def _realistic_sizes() -> dict:
    """Realistic magnitudes of the catalogue effects' parameters, by name."""
    from .effects import CATALOGUE
    out = {}
    for e in CATALOGUE.values():
        out.update({k: float(v) for k, v in e.realistic.items()})
    return out


def check_plausibility(fit: EstimationResult, *, uncertainty=None, level: float = 0.05,
                       drag_range: tuple = (0.05, 1.5), mach_degree: int = 2, mach_tolerance: float = 0.05,
                       transonic: bool = True,
                       subsonic_spread: float = 0.5, effect_factor: float = 5.0,
                       realistic: dict | None = None, supersonic_tolerance: float = 0.05) -> Plausibility:
    """Check the estimated coefficients of ``fit`` (item 3 of the diagnosis).

    Parameters
    ----------
    fit : EstimationResult
    uncertainty : rocketid.estimability.Uncertainty, optional
        Standard errors and covariance (computed with
        :func:`rocketid.estimability.uncertainty` when not given).
    level : float
        Significance of the Mach-consistency test.
    drag_range : (float, float)
        Plausible drag coefficients of a launch vehicle.
    mach_degree : int
        Degree of the polynomial part of the smooth drag curve.
    mach_tolerance : float
        ``tau`` of the Mach-consistency test (drag-coefficient units).
    transonic : bool
        Add the transonic drag-rise term to the smooth drag curve (default).
    subsonic_spread : float
        Largest plausible relative spread of time-knot drag below Mach 0.8.
    effect_factor : float
        An effect parameter larger than this many times its realistic size is implausible.
    realistic : dict, optional
        ``{parameter name: realistic magnitude}`` of the effects added to the model (default:
        from the effects catalogue). When given, its parameters are effect parameters whatever
        roles they enter: a wind's surface value enters the drag coefficient through the Mach
        number of the airspeed, yet it is a speed, not a drag coefficient.
    supersonic_tolerance : float
        Largest rise of the drag coefficient with the Mach number above :data:`SUPERSONIC_MACH`
        (drag-coefficient units) beyond two standard errors that is not flagged.

    Returns
    -------
    Plausibility
    """
    if not isinstance(fit, EstimationResult):
        raise SettingsError(f"check_plausibility() needs an EstimationResult, got {type(fit).__name__}")
    if not 0 < level < 1:
        raise SettingsError(f"level must be in (0, 1), got {level}")
    if mach_degree < 0 or mach_tolerance < 0:
        raise SettingsError("mach_degree and mach_tolerance must be non-negative")
    spec = fit.spec
    names = spec.parameter_names
    p = np.asarray(fit.p, float)
    se, cov, notes = _standard_errors(fit, uncertainty)
    by_role, kind_notes = coefficient_kinds(spec)
    effect_names = set(realistic) if realistic is not None else set()
    kinds = tuple("effect" if n in effect_names else by_role[n] for n in names)
    notes += kind_notes
    real = _realistic_sizes() if realistic is None else dict(realistic)
    flags = _coefficient_flags(fit, se, kinds, real, drag_range, effect_factor)
    mach_checks, shape_flags, shape_notes = _drag_shape_checks(fit, se, cov, level, mach_degree, mach_tolerance,
                                                               transonic, subsonic_spread)
    flags += shape_flags
    notes += shape_notes
    rise = _supersonic_rise(fit, cov, supersonic_tolerance)
    if rise is not None:
        flags.append(rise)
    order = {s: i for i, s in enumerate(SEVERITIES)}
    flags.sort(key=lambda f: order[f.severity])
    return Plausibility(model=spec.name, names=names, estimates=p, standard_errors=se, lower=spec.lower,
                        upper=spec.upper, kinds=kinds, flags=tuple(flags), mach_checks=tuple(mach_checks),
                        level=float(level), notes=tuple(notes))


def _standard_errors(fit: EstimationResult, uncertainty) -> tuple[np.ndarray, np.ndarray | None, list]:
    """``(standard errors, covariance or None, notes)`` of the fit's parameters (NaN when the
    uncertainty cannot be formed)."""
    notes = []
    cov = None
    se = np.full(len(fit.spec.parameter_names), np.nan)
    if uncertainty is None:
        try:
            from ..estimability import uncertainty as _uncertainty
            uncertainty = _uncertainty(fit)
        except RocketidError as exc:
            notes.append(f"standard errors are not available ({exc}); the checks use the estimates alone")
    if uncertainty is not None:
        se = np.asarray(uncertainty.standard_errors, float)
        cov = np.asarray(uncertainty.parameter_covariance, float)
        if fit.chi2_per_dof > 1.5:
            notes.append(f"chi2/dof = {fit.chi2_per_dof:.3g}: standard errors assume the stated sigma and are "
                         f"too small by about sqrt({fit.chi2_per_dof:.3g}); the residuals also fail (see compare)")
    return se, cov, notes


def _coefficient_flags(fit: EstimationResult, se: np.ndarray, kinds: tuple, real: dict, drag_range: tuple,
                       effect_factor: float) -> list[Flag]:
    """Each parameter on its own: at a bound, a drag coefficient or lift slope of the wrong sign, a
    drag coefficient out of range, an effect beyond its realistic size, a standard error above the value."""
    spec = fit.spec
    p, lo, hi = np.asarray(fit.p, float), spec.lower, spec.upper
    flags = []
    at_bound = {str(s): side for s, side in fit.active_bounds(rtol=1e-5)}
    for i, n in enumerate(spec.parameter_names):
        v, s, kind = p[i], se[i], kinds[i]
        sd = f" +- {s:.2g}" if np.isfinite(s) else ""
        if n in at_bound:
            side = at_bound[n]
            b = lo[i] if side == "lower" else hi[i]
            extra = ""
            if kind == "drag" and side == "lower" and b <= drag_range[0]:
                extra = " (the data want a drag coefficient near zero or negative)"
            elif kind == "drag" and side == "upper" and b >= drag_range[1] * 0.66:
                extra = " (the data want an even larger drag coefficient)"
            flags.append(Flag("at-bound", "fail", (n,), f"{n} = {v:.4g} is at its {side} bound {b:g}{extra}: "
                                                        "the estimate is held by the bound, not determined by the data"))
        if kind in ("drag", "lift slope") and v < 0:
            flags.append(Flag("wrong-sign", "fail", (n,), f"{n} = {v:.4g}{sd} is negative: a "
                              f"{'drag coefficient' if kind == 'drag' else 'lift slope'} cannot be"))
        elif kind == "drag" and n not in at_bound:
            tol = 2 * s if np.isfinite(s) else 0.0
            if v + tol < drag_range[0] or v - tol > drag_range[1]:
                flags.append(Flag("implausible", "fail", (n,), f"{n} = {v:.4g}{sd} is outside the plausible range "
                                  f"{drag_range[0]:g}-{drag_range[1]:g} of a launch vehicle's drag coefficient"))
        if n in real and real[n] != 0 and abs(v) > effect_factor * abs(real[n]):
            flags.append(Flag("implausible", "warn", (n,), f"{n} = {v:.4g}{sd} is {abs(v / real[n]):.0f} times its "
                              f"realistic size {real[n]:g}"))
        if np.isfinite(s) and s > abs(v) and n not in at_bound:
            flags.append(Flag("undetermined", "info", (n,), f"{n} = {v:.4g} has a standard error {s:.3g} larger than "
                              "itself: the data hardly determine it"))
    return flags


def _drag_shape_checks(fit: EstimationResult, se: np.ndarray, cov, level: float, mach_degree: int,
                       mach_tolerance: float, transonic: bool,
                       subsonic_spread: float) -> tuple[list, list[Flag], list[str]]:
    """``(mach_checks, flags, notes)``: each time-knot drag family against a smooth function of Mach
    (``mach-smooth``), and its spread below Mach 0.8 (``subsonic-flat``)."""
    spec = fit.spec
    mach_checks, flags, notes = [], [], []
    cd_role = spec.role("drag_coefficient")
    if cd_role is not None:
        used = spec.expand(cd_role).free_symbols
        drag_fams = [f for f in spec.families if f.symbol in used]
    else:
        drag_fams = [f for f in spec.families if _kind(str(f.knots[0])) == "drag" or str(f.symbol).upper().startswith("CD")]
    mach = spec.role("mach")
    if drag_fams and mach is None:
        notes.append(f"model {spec.name!r} declares no 'mach' role: the time-knot drag cannot be checked against Mach "
                     "(declare it with m.declare_role('mach', symbol))")
        return mach_checks, flags, notes
    for fam in drag_fams:
        mc = _mach_check(fit, fam, mach, se, cov, mach_degree, mach_tolerance, transonic)
        if mc is None:
            notes.append(f"{fam.symbol}: too few distinct knots (or Mach numbers) for the Mach-consistency check")
            continue
        mach_checks.append(mc)
        if mc.p_value < level:
            worst = np.argsort(-np.abs(mc.standardized))[:3]
            who = ", ".join(f"{mc.knots[j]} = {mc.values[j]:.3g} at Mach {mc.mach[j]:.2f} "
                            f"({mc.standardized[j]:+.1f})" for j in sorted(worst))
            flags.append(Flag("mach-smooth", "fail", tuple(mc.knots[j] for j in sorted(worst)),
                              f"{fam.symbol}(t) is not a smooth function of Mach: the best smooth drag curve "
                              f"({mc.family_name}) misses the knots by chi2 = {mc.statistic:.3g} on {mc.dof} dof "
                              f"(p = {mc.p_value:.2g}, tolerance {mc.tolerance:g}); worst {who}"))
        sub = mc.mach < 0.8
        if sub.sum() >= 2:
            vals = mc.values[sub]
            spread = float(vals.max() - vals.min())
            mean = float(np.mean(np.abs(vals)))
            err = float(np.nanmax(mc.standard_errors[sub])) if np.any(np.isfinite(mc.standard_errors[sub])) else 0.0
            if mean > 0 and spread > subsonic_spread * mean and spread > 3 * err:
                ks = tuple(k for k, s_ in zip(mc.knots, sub) if s_)
                flags.append(Flag("subsonic-flat", "warn", ks,
                                  f"{fam.symbol} varies from {vals.min():.3g} to {vals.max():.3g} "
                                  f"({100 * spread / mean:.0f} % of its mean) between knots below Mach 0.8 "
                                  f"({', '.join(ks)}); a slender body's subsonic drag is nearly constant"))
    return mach_checks, flags, notes


TRANSONIC_CENTRE = 1.1
TRANSONIC_WIDTH = 0.25

SUPERSONIC_MACH = 1.5
"""Above this Mach number a launch vehicle's drag coefficient falls with the Mach number (module notes)."""

SUPERSONIC_SPAN = 0.3
"""The supersonic check needs at least this span of Mach numbers flown above :data:`SUPERSONIC_MACH`."""


def _monotonic_pieces(mach: np.ndarray, keep: np.ndarray) -> list[np.ndarray]:
    """The kept node indices, in time order, split where the Mach number turns (it climbs under thrust and
    falls in a coast): the drag coefficient is judged against the Mach number within each piece, so that a
    drag that differs with the motor on and off at the same Mach number (power-off base drag) is not read
    as a rise with Mach."""
    idx = np.flatnonzero(keep)
    if idx.size < 2:
        return [idx]
    step = np.sign(np.diff(mach[idx]))
    turns = [k + 1 for k in range(1, step.size) if step[k] != 0 and step[k - 1] != 0 and step[k] != step[k - 1]]
    return np.split(idx, turns)


def _supersonic_rise(fit: EstimationResult, cov, tolerance: float) -> Flag | None:
    """The ``supersonic-rise`` flag of ``fit`` (module notes), or None (no rise, or no roles, or too little
    supersonic flight to tell)."""
    spec = fit.spec
    cd_sym, mach_sym = spec.role("drag_coefficient"), spec.role("mach")
    if cd_sym is None or mach_sym is None or tolerance < 0:
        return None
    times = np.asarray(fit.node_times, float)
    states = np.asarray(fit.state_trajectories, float)
    p = np.asarray(fit.p, float)
    cd_expr = spec.expand(cd_sym)
    with np.errstate(all="ignore"):
        mach = evaluate_along(spec, mach_sym, times, states, p)
        cd = evaluate_along(spec, cd_expr, times, states, p)
    keep = np.isfinite(mach) & np.isfinite(cd) & (mach >= SUPERSONIC_MACH)
    best = None
    for piece in _monotonic_pieces(mach, keep):
        if piece.size < 3 or np.ptp(mach[piece]) < SUPERSONIC_SPAN:
            continue
        idx = piece[np.argsort(mach[piece], kind="stable")]
        rises = cd[idx] - np.minimum.accumulate(cd[idx])
        b = int(np.argmax(rises))
        if best is None or rises[b] > best[2][best[1]]:
            best = (idx, b, rises)
    if best is None or best[2][best[1]] <= tolerance:
        return None
    idx, b, rises = best
    m, c = mach[idx], cd[idx]
    a = int(np.argmin(c[:b + 1]))
    names = spec.parameter_names
    used = {str(x) for x in cd_expr.free_symbols}
    cols = [i for i, n in enumerate(names) if n in used]
    sd = 0.0
    if cov is not None and cols:
        # gradient of CD(M_b) - CD(M_a) in the parameters, the states held at the fit
        pts = idx[[a, b]]
        g = np.zeros(len(names))
        for i in cols:
            step = 1e-6 * max(1.0, abs(p[i]))
            q = p.copy()
            q[i] += step
            with np.errstate(all="ignore"):
                moved = evaluate_along(spec, cd_expr, times[pts], states[pts], q)
            g[i] = ((moved[1] - moved[0]) - (cd[pts[1]] - cd[pts[0]])) / step
        var = float(g @ np.asarray(cov, float) @ g)
        sd = float(np.sqrt(var)) if np.isfinite(var) and var > 0 else 0.0
    if rises[b] <= tolerance + 2 * sd:
        return None
    kinds = coefficient_kinds(spec)[0]
    drag = tuple(n for n in names if n in used and kinds[n] == "drag") or tuple(names[i] for i in cols)
    return Flag("supersonic-rise", "fail", drag,
                f"the drag coefficient rises from {c[a]:.3g} at Mach {m[a]:.2f} to {c[b]:.3g} at Mach {m[b]:.2f} "
                f"(+{rises[b]:.3g} +- {sd:.2g}; tolerance {tolerance:g}): above Mach {SUPERSONIC_MACH:g} a launch "
                "vehicle's drag falls with the Mach number, so the drag is standing in for another effect "
                "(a thrust or mass error late in the flight, a wind aloft)")


def _basis(mach: np.ndarray, degree: int, transonic: bool) -> np.ndarray:
    X = np.vander(mach, degree + 1)
    if transonic:
        X = np.column_stack([X, np.exp(-((mach - TRANSONIC_CENTRE) / TRANSONIC_WIDTH) ** 2 / 2)])
    return X


def _mach_check(fit, fam, mach_sym, se, cov, degree, tau, transonic) -> MachConsistency | None:
    from scipy.stats import chi2

    spec = fit.spec
    names = spec.parameter_names
    times = np.asarray(fam.breakpoints, float)
    knots = [str(k) for k in fam.knots]
    # tied knots appear once
    seen, keep = set(), []
    for j, k in enumerate(knots):
        if k not in seen:
            seen.add(k)
            keep.append(j)
    times = times[keep]
    knots = [knots[j] for j in keep]
    idx = [names.index(k) for k in knots]
    states = fit.states_at(times)
    with np.errstate(all="ignore"):
        mach = evaluate_along(spec, mach_sym, times, states, fit.p)
    y = np.asarray(fit.p, float)[idx]
    n = y.size
    X = _basis(mach, degree, transonic) if np.all(np.isfinite(mach)) else None
    if X is None or n - X.shape[1] < 1 or np.linalg.matrix_rank(X) < X.shape[1]:
        return None
    if cov is not None:
        C = cov[np.ix_(idx, idx)]
    else:
        C = np.diag(np.nan_to_num(se[idx], nan=0.0) ** 2)
    V = C + tau ** 2 * np.eye(n)
    W = np.linalg.pinv(V, hermitian=True)
    b = np.linalg.lstsq(X.T @ W @ X, X.T @ W @ y, rcond=None)[0]
    r = y - X @ b
    stat = float(r @ W @ r)
    dof = n - X.shape[1]
    sd = np.sqrt(np.clip(np.diag(V), 1e-300, None))
    return MachConsistency(family=str(fam.symbol), knots=tuple(knots), times=times, mach=mach, values=y,
                           standard_errors=np.asarray(se[idx], float), smooth=X @ b, coefficients=b,
                           standardized=r / sd, statistic=stat, dof=int(dof), p_value=float(chi2.sf(stat, dof)),
                           degree=int(degree), tolerance=float(tau), transonic=bool(transonic))
