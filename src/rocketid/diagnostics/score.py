"""Ranking candidate effects at the base fit by the score (Lagrange-multiplier) test, without refitting.

At the base fit ``p_hat`` every candidate effect is added at once, at zero, to
one augmented model. Its trajectory at ``(p_hat, beta = 0)`` is the base fit's
(the effects vanish there), so the base collocation states are feasible for
it, and one sparse LU of the KKT block ``J_w`` gives the output sensitivities
to every parameter (:func:`rocketid.sensitivity.sensitivity_at`). Then, with
residuals ``r`` (model minus measurement), noise covariance ``R`` and ``S``
the sensitivities of the estimated parameters::

    s~_k = s_k - S (S^T R^-1 S)^-1 S^T R^-1 s_k        (what the fit could not absorb)
    g_k  = s~_k^T R^-1 r,   I_k = s~_k^T R^-1 s~_k
    LM_k = g_k^T I_k^-1 g_k  ~  chi2(dof_k)            (dof_k = parameters of effect k)

``LM_k / 2`` is the predicted fall of the objective ``J`` when the effect is
added (to first order), and ``-I_k^-1 g_k`` the one-step (Gauss-Newton)
estimate of its parameters from the base fit.

Reported beside each statistic (thresholds are module constants):

* p-values corrected for the number of candidates by Holm's step-down method
  (it controls the family-wise error rate like Bonferroni, and is uniformly
  more powerful);
* confounded groups: a candidate joins the group of a better-ranked one when
  their score statistics are nearly equal (ratio >= :data:`SCORE_RATIO`) and
  the output changes they would make, ``u_k = s~_k I_k^-1 g_k`` (weighted by
  ``R^-1/2``), are nearly collinear (``|cos| >=`` :data:`COLLINEAR_COS`): the
  data cannot tell them apart at this fit, only a refit can (and sometimes
  not even that);
* absorption: when the projection removes more than :data:`ABSORBED` of the
  squared norm of an effect's sensitivity (for a multi-parameter effect, of
  its least-absorbed combination), the estimated parameters would absorb
  the effect; the parameter families that absorb it are named ("confounded
  with CD(t): it would be absorbed into the drag estimate"). The note adds
  whether what is left would still be seen at a realistic size of the
  effect (expected statistic above :data:`DETECTABLE`) -- then the base fit
  has distorted those coefficients -- or would go unseen.

Notation
--------
==========  =================================================================
``Sw``      ``R^-1/2 S``: sensitivities divided by each sample's sigma
``rw``      ``R^-1/2 r``
``U``       orthonormal basis of the estimated parameters' columns of ``Sw``
``rho_k``   retained share: ``||s~_k|| / ||s_k||`` (1: nothing absorbed)
==========  =================================================================
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Iterable, NamedTuple, Sequence

import numpy as np
from scipy import stats

from ..errors import ModelError, RocketidError, SettingsError
from ..model import ModelSpec
from ..sensitivity import sensitivity_at
from ..solve import EstimationResult, Prepared, prepare
from ..summary import Section, Summary, SummaryText, Table
from .effects import CATALOGUE, Effect, apply_effect, effect_parameter_problems, is_present, resolve_effects

__all__ = ["CandidateScore", "CandidateRanking", "AugmentedModel", "augment", "rank_candidates", "holm", "onset_starts",
           "scan_peak", "ScanPeak", "COLLINEAR_COS", "SCORE_RATIO", "ABSORBED", "DETECTABLE"]

COLLINEAR_COS = 0.95
"""|cos| of the projected, R^-1-weighted output changes above which two candidates are collinear."""

SCORE_RATIO = 0.8
"""Smaller over larger score statistic above which two collinear candidates are one group."""

ABSORBED = 0.95
"""Share of an effect's squared sensitivity norm removed by the projection above which it is absorbed."""

DETECTABLE = 25.0
"""Expected score statistic (non-centrality) at a realistic size below which an absorbed effect goes unseen."""

PARTLY_ABSORBED = 0.5
"""Share above which the note says the effect is partly absorbed (and biases those estimates)."""

_ROLE_WORDS = {"drag_coefficient": "the drag estimate", "lift_coefficient": "the lift estimate",
               "drag": "the drag estimate", "lift": "the lift estimate", "thrust": "the thrust estimate",
               "mass": "the mass estimate", "density": "the density estimate",
               "thrust_direction": "the thrust-direction estimate"}


@dataclass(frozen=True)
class CandidateScore:
    """The score test of one candidate effect at the base fit.

    Attributes
    ----------
    name, title : str
    statistic : float
        The score (LM) statistic.
    dof : int
        Its degrees of freedom (parameters of the effect the data can see).
    p_value : float
        ``P(chi2(dof) > statistic)``, uncorrected.
    p_value_corrected : float
        Holm-corrected over the number of scored candidates.
    predicted_drop : float
        Predicted fall of the objective ``J`` (= statistic / 2) when the effect is added.
    group : int
        Id (1, 2, ...) of its confounded group, numbered in rank order.
    absorbed_by : list of str or None
        Estimated parameters that would absorb the effect (all knots of the
        families named in the note): they take up more than :data:`ABSORBED`
        of its signature. Whether what is left is still detectable at a
        realistic size is ``realistic_statistic`` (and the note).
    significant : bool
        ``p_value_corrected < level``.
    note : str
    kind : str
    parameters : tuple of str
        The effect's parameters.
    retained : float
        ``||s~|| / ||s||`` of its least-absorbed combination (1: nothing absorbed).
    one_step : dict
        One-step (Gauss-Newton) estimate of its parameters from the base fit.
    rank : int
        1 for the most significant.
    realistic_statistic : float or None
        The expected score statistic (non-centrality ``||s~ beta||^2``) were
        the effect present at a realistic size, ``|beta_j| <=`` its realistic
        magnitude: for one parameter exactly, for k an upper bound (the
        ellipsoid ``beta = D w``, ``|w| <= sqrt(k)``, holding that box). Below
        :data:`DETECTABLE` an absorbed effect would go unseen. None when the
        effect declares no realistic magnitude.
    """

    name: str
    title: str
    statistic: float
    dof: int
    p_value: float
    p_value_corrected: float
    predicted_drop: float
    group: int
    absorbed_by: list | None
    significant: bool
    note: str
    kind: str = ""
    parameters: tuple = ()
    retained: float = 1.0
    one_step: dict = field(default_factory=dict)
    rank: int = 0
    realistic_statistic: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready; ``p_value`` is the corrected p-value (``p_value_raw`` the uncorrected)."""
        return {"name": self.name, "title": self.title, "kind": self.kind, "rank": self.rank,
                "statistic": float(self.statistic), "dof": int(self.dof),
                "p_value": float(self.p_value_corrected), "p_value_raw": float(self.p_value),
                "predicted_drop": float(self.predicted_drop), "group": int(self.group),
                "absorbed_by": list(self.absorbed_by) if self.absorbed_by else None,
                "significant": bool(self.significant), "retained": float(self.retained),
                "parameters": list(self.parameters), "one_step": {k: float(v) for k, v in self.one_step.items()},
                "realistic_statistic": None if self.realistic_statistic is None else float(self.realistic_statistic),
                "note": self.note}


@dataclass(frozen=True)
class CandidateRanking:
    """Candidate effects ranked by the score test at one fit.

    Attributes
    ----------
    candidates : list of CandidateScore
        Best first (smallest p-value, then largest statistic).
    groups : list of list of str
        Confounded groups, in rank order of their best member.
    skipped : dict
        ``{name: reason}`` for candidates that could not be scored.
    level : float
    correction : str
        ``"holm"``.
    base : dict
        The base fit: model, objective, chi2/dof, number of data.
    notes : tuple of str
    timings : dict
        ``build_s`` (augmented model), ``prepare_s`` (code generation, NLP),
        ``sensitivity_s`` (one LU, all columns), ``score_s``, ``total_s``;
        ``codegen_cached``.
    augmented : AugmentedModel
        The augmented model, reusable by another ranking on the same mesh and sample times.
    explained : dict
        ``{name: {channel: array}}``: the part of each channel's residual
        (model minus measurement, at its samples) that the candidate would
        remove to first order -- where in the flight it acts.
    """

    candidates: list
    groups: list
    skipped: dict
    level: float
    correction: str
    base: dict
    notes: tuple
    timings: dict
    augmented: "AugmentedModel | None" = field(default=None, repr=False, compare=False)
    explained: dict = field(default_factory=dict, repr=False, compare=False)

    def __getitem__(self, name: str) -> CandidateScore:
        for c in self.candidates:
            if c.name == name:
                return c
        raise KeyError(f"no scored candidate named {name!r}; scored: {', '.join(self.names)}"
                       + (f"; skipped: {', '.join(self.skipped)}" if self.skipped else ""))

    def effect(self, name: str) -> Effect:
        """The :class:`Effect` scored under ``name`` (to pass on to ``confirm``, custom effects too)."""
        self[name]
        return next(e for e in self.augmented.effects if e.name == name)

    @property
    def names(self) -> list[str]:
        """Candidate names, best first."""
        return [c.name for c in self.candidates]

    @property
    def significant(self) -> list[CandidateScore]:
        return [c for c in self.candidates if c.significant]

    def group_of(self, name: str) -> list[str]:
        """The confounded group holding ``name``."""
        g = self[name].group
        return list(self.groups[g - 1])

    def to_dict(self) -> dict:
        """``{"candidates": [{"name", "statistic", "p_value" (corrected), "group", ...}], ...}`` best first."""
        return {"candidates": [c.to_dict() for c in self.candidates],
                "groups": [list(g) for g in self.groups],
                "skipped": dict(self.skipped), "level": self.level, "correction": self.correction,
                "base": dict(self.base), "notes": list(self.notes),
                "timings": {k: (float(v) if not isinstance(v, bool) else v) for k, v in self.timings.items()}}

    def summary(self) -> SummaryText:
        """The base fit and the test, a table of the candidates, best first, then numbered notes: a
        :class:`~rocketid.summary.Summary`, as its text (:class:`~rocketid.summary.SummaryText`)."""
        b = self.base
        head = Section("", (
            ("base fit", f"J = {b['objective']:.6g}, chi2/dof = {b['chi2_per_dof']:.4g} ({b['n_data']} data, "
                         f"{b['n_estimated']} estimated)"),
            ("test", f"score (LM) statistic ~ chi2(dof); p corrected by {self.correction.title()} over "
                     f"{len(self.candidates)} candidates; level {self.level:g}"),
            ("time", f"{self.timings.get('total_s', float('nan')):.2f} s (sensitivities "
                     f"{self.timings.get('sensitivity_s', float('nan')):.2f} s)")))
        notes: list[str] = []
        rows = []
        for c in self.candidates:
            flags = []
            if c.significant:
                flags.append("*")
            if c.absorbed_by:
                unseen = c.realistic_statistic is None or c.realistic_statistic < DETECTABLE
                flags.append("absorbed" if unseen else "absorbed(visible)")
            if len(self.groups[c.group - 1]) > 1:
                flags.append("confounded")
            if c.note:
                notes.append(f"{c.name}: {c.note}")
                flags.append(f"[{len(notes)}]")
            rows.append((c.rank, c.name, c.statistic, c.dof, _fmt_p(c.p_value_corrected), c.predicted_drop, c.group,
                         " ".join(flags)))
        table = Section("Candidates (best first)", (
            Table(("#", "effect", "LM", "dof", "p (corr.)", "drop of J", "group", "flags"), rows,
                  (None, None, ".4g", None, None, ".4g")),
            "(* significant at the level; LM / 2 is the predicted fall of J when the effect is added)"))
        notes += [f"{name} was not scored: {why}" for name, why in self.skipped.items()]
        notes.extend(self.notes)
        return SummaryText(Summary(f"rocketid candidate effects: score test at the fit of {b['model']}",
                                   (head, table), tuple(notes)))


def _fmt_p(p: float) -> str:
    if p == 0.0:
        return "<1e-300"
    return f"{p:.3g}" if p >= 1e-3 else f"{p:.1e}"


def holm(p: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error rate)."""
    p = np.asarray(p, float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adj = np.empty(m)
    running = 0.0
    for i, k in enumerate(order):
        running = max(running, min(1.0, (m - i) * p[k]))
        adj[k] = running
    return adj


# ---------------------------------------------------------------------------
# the augmented model
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class AugmentedModel:
    """The base model with every scored candidate at zero, collocated on the fit's mesh.

    Attributes
    ----------
    spec : ModelSpec
    prepared : Prepared
    effects : tuple of Effect
        The candidates it holds, in order.
    parameters : dict
        ``{effect name: tuple of parameter names}``.
    skipped : dict
        ``{effect name: reason}``.
    base_fingerprint : str
    build_s, prepare_s : float
    """

    spec: ModelSpec
    prepared: Prepared
    effects: tuple
    parameters: dict
    skipped: dict
    base_fingerprint: str
    build_s: float
    prepare_s: float

    def compatible(self, fit: EstimationResult, effects: Sequence[Effect]) -> bool:
        """Whether it serves a ranking of ``effects`` at ``fit`` (same model, mesh and sample times)."""
        if self.base_fingerprint != fit.spec.fingerprint():
            return False
        if sorted([e.name for e in self.effects] + list(self.skipped)) != sorted(e.name for e in effects):
            return False
        given = {e.name: e for e in effects}
        if any(given[e.name] is not e for e in self.effects):      # the same Effect values (custom ones too)
            return False
        mine, theirs = self.prepared.transcription.mesh, fit.prepared.transcription.mesh
        if mine.K != theirs.K or not np.array_equal(mine.boundaries, theirs.boundaries):
            return False
        a, b = self.prepared.measurements, fit.prepared.measurements
        if a.names != b.names:
            return False
        return all(np.array_equal(a[n].times, b[n].times) and np.array_equal(np.asarray(a[n].sigma), np.asarray(b[n].sigma))
                   for n in a.names)


def augment(fit: EstimationResult, candidates: Iterable[Effect | str] | None = None) -> AugmentedModel:
    """Build the augmented model of ``candidates`` (default: the whole catalogue) for ``fit``.

    Candidates already in the model, or that need something the model lacks,
    are left out with a reason (:attr:`AugmentedModel.skipped`).
    """
    t0 = time.perf_counter()
    base = fit.spec
    effects = resolve_effects(list(CATALOGUE.values()) if candidates is None else list(candidates))
    skipped: dict[str, str] = {}
    usable: list[Effect] = []
    for e in effects:
        if is_present(base, e):
            skipped[e.name] = "it is already in the model"
            continue
        try:
            apply_effect(base.to_model(), e)
        except ModelError as exc:
            skipped[e.name] = str(exc)
            continue
        usable.append(e)
    while True:
        m = base.to_model()
        declared, clash = {}, None
        for e in usable:
            try:
                declared[e.name] = apply_effect(m, e)
            except ModelError as exc:
                clash = (e, str(exc))
                break
        if clash is not None:
            skipped[clash[0].name] = f"it clashes with the candidates before it: {clash[1]}"
            usable.remove(clash[0])
            continue
        spec = m.freeze()
        problems = effect_parameter_problems(spec, declared, base.parameter_names)
        if problems:
            skipped.update(problems)
            usable = [e for e in usable if e.name not in problems]
            continue
        break
    if not usable:
        raise ModelError("no candidate effect applies to model "
                         f"{base.name!r}: " + "; ".join(f"{k}: {v}" for k, v in skipped.items()))
    if any(spec.parameter(s).guess != g for s, g in zip(base.parameter_symbols, base.guess)):
        spec = spec.with_guess({s: g for s, g in zip(base.parameter_symbols, base.guess)})
    build = time.perf_counter() - t0
    t1 = time.perf_counter()
    prep = prepare(spec, fit.prepared.measurements, mesh=fit.prepared.transcription.mesh)
    return AugmentedModel(spec, prep, tuple(usable), {k: tuple(map(str, v)) for k, v in declared.items()},
                          skipped, base.fingerprint(), build, time.perf_counter() - t1)


# ---------------------------------------------------------------------------
# the test
# ---------------------------------------------------------------------------


def _families(spec: ModelSpec, names: Sequence[str]) -> list[tuple[str, list[int]]]:
    """Group estimated parameters into families: ``(label, indices)``.

    Knots of a time family are ``<F>(t)``; knots of a table (:attr:`ModelSpec.tables`) are
    ``<name>(M)`` when its variable plays the Mach role, ``<name>(q)`` the dynamic pressure,
    else ``<name>(..)``; every other parameter is its own family.
    """
    short = {"mach": "M", "dynamic_pressure": "q", "attack_angle": "alpha"}
    fam_of: dict[str, str] = {}
    for ps in spec.parameters:
        n = str(ps.symbol)
        if n not in names:
            continue
        if ps.family is not None:
            fam_of[n] = f"{ps.family}(t)"
            continue
        tb = spec.table_of(ps.symbol)
        if tb is not None and sum(str(k) in names for k in tb.parameters) >= 2:
            fam_of[n] = f"{tb.name}({short.get(tb.variable_role, '..')})"
        else:
            fam_of[n] = n
    out: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        out.setdefault(fam_of.get(n, n), []).append(i)
    return list(out.items())


def _meaning(spec: ModelSpec, members: Sequence[str]) -> str:
    """Which estimate a family feeds ("the drag estimate"), through the model's roles."""
    by_name = {str(p.symbol): p for p in spec.parameters}
    syms = {by_name[n].symbol for n in members}
    fams = {by_name[n].family for n in members} - {None}
    role_of = {expr: role for role, expr in spec.roles}
    for d, e in spec.definitions:
        if (syms | fams) & e.free_symbols and role_of.get(d) in _ROLE_WORDS:
            return _ROLE_WORDS[role_of[d]]
    return "the estimates of " + ", ".join(members)


def _tdot(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^T b`` for tall, thin ``A`` (and ``b``) without BLAS: a multi-threaded BLAS is
    slow on these shapes on a busy machine (20 ms instead of 0.02 ms)."""
    return np.einsum("ij,i...->j...", A, b)


def _orthonormal(X: np.ndarray) -> np.ndarray:
    if X.shape[1] == 0:
        return np.zeros((X.shape[0], 0))
    norms = np.sqrt(np.einsum("ij,ij->j", X, X))
    keep = norms > 0
    U, s, _ = np.linalg.svd(X[:, keep] / norms[keep], full_matrices=False)
    return U[:, s > s[0] * 1e-10] if s.size else U[:, :0]


def rank_candidates(fit: EstimationResult, candidates: Iterable[Effect | str] | None = None, *,
                    level: float = 0.05, augmented: AugmentedModel | None = None) -> CandidateRanking:
    """Rank candidate effects at ``fit`` by the score test (module notes), without refitting.

    Parameters
    ----------
    fit : EstimationResult
        The converged base fit.
    candidates : iterable of Effect or str, optional
        Default: the whole :data:`~rocketid.diagnostics.effects.CATALOGUE`
        (those that cannot apply to the model are skipped with a note).
    level : float
        Significance level of the corrected p-values.
    augmented : AugmentedModel, optional
        Reuse the augmented model of an earlier ranking with the same model,
        candidates, mesh and sample times (``ranking.augmented``): saves
        building and collocating it again.

    Returns
    -------
    CandidateRanking

    Raises
    ------
    SettingsError
        A level outside (0, 1).
    SensitivityError
        The sensitivities cannot be formed at the fit.
    """
    if not (0.0 < float(level) < 1.0):
        raise SettingsError(f"level must be in (0, 1), got {level!r}")
    t_start = time.perf_counter()
    effects = resolve_effects(list(CATALOGUE.values()) if candidates is None else list(candidates))
    notes: list[str] = []
    if not fit.success:
        notes.append(f"the base fit did not converge ({fit.message}): the score test assumes a converged fit")
    reused = augmented is not None and augmented.compatible(fit, effects)
    if augmented is not None and not reused:
        notes.append("the augmented model given does not match this fit (model, candidates, mesh or sample times); "
                     "it was built again")
    aug = augmented if reused else augment(fit, effects)
    t1 = time.perf_counter()
    sens = _augmented_sensitivities(fit, aug)
    t2 = time.perf_counter()
    proj = _base_projection(fit, sens)
    n_p = len(fit.spec.parameters)
    # all candidate columns projected at once: s~ = s - U U^T s
    C = proj.Sw[:, n_p:]
    Ct = C - proj.U @ (proj.U.T @ C)
    index = {n: i - n_p for i, n in enumerate(aug.spec.parameter_names) if i >= n_p}
    meanings: dict = {}
    raw = []
    for e in aug.effects:
        cols = [index[n] for n in aug.parameters[e.name]]
        raw.append(_score_one(e, C[:, cols], Ct[:, cols], proj.rw, proj.families, fit.spec, proj.estimated, meanings))
    logp = np.array([r["logp"] for r in raw])
    lm = np.array([r["statistic"] for r in raw])
    order = sorted(range(len(raw)), key=lambda i: (logp[i], -lm[i]))
    groups = _group_confounded(raw, order)
    scores = _candidate_scores(raw, order, groups, aug, level)
    t4 = time.perf_counter()
    timings = {"build_s": 0.0 if reused else aug.build_s, "prepare_s": 0.0 if reused else aug.prepare_s,
               "sensitivity_s": t2 - t1, "score_s": t4 - t2, "total_s": t4 - t_start,
               "codegen_cached": bool(aug.prepared.codegen_cached), "reused_augmented_model": bool(reused)}
    base_info = {"model": fit.spec.name, "objective": float(fit.objective), "chi2_per_dof": float(fit.chi2_per_dof),
                 "n_data": int(fit.n_data), "n_estimated": int(fit.n_estimated)}
    sigma, slices = sens.sigma, sens.channel_slices
    explained = {aug.effects[i].name: {ch: raw[i]["direction"][sl] * sigma[sl] for ch, sl in slices.items()}
                 for i in order}
    return CandidateRanking(scores, [[aug.effects[j].name for j in g] for g in groups.groups],
                            dict(aug.skipped), float(level), "holm", base_info,
                            tuple(notes + list(proj.notes) + list(sens.notes)), timings, aug, explained)


def _augmented_sensitivities(fit: EstimationResult, aug: AugmentedModel):
    """The output sensitivities of the augmented model at the base fit (effects at zero): the base
    fit's collocation states, extended by the effects' own states at their initial values."""
    spec_a, base = aug.spec, fit.spec
    n_p = len(base.parameters)
    if tuple(spec_a.parameter_names[:n_p]) != base.parameter_names:
        raise ModelError("the augmented model does not start with the base model's parameters")
    if aug.prepared.nlp.channel_names != fit.nlp.channel_names:
        raise ModelError("the augmented model's channels differ from the fit's")
    lay_b = fit.prepared.transcription.layout
    lay_a = aug.prepared.transcription.layout
    S_b, _ = lay_b.unpack(fit.nlp.full_vector(fit.x))
    S_a = np.tile(spec_a.initial_state(spec_a.guess), (lay_a.n_nodes, 1))
    S_a[:, :S_b.shape[1]] = S_b
    p_a = np.concatenate([fit.p, np.zeros(len(spec_a.parameters) - n_p)])
    return sensitivity_at(aug.prepared, p_a, gamma=S_a.ravel(), solve=True)


class _Projection(NamedTuple):
    """What the base fit's estimated parameters can absorb (module notation)."""

    Sw: np.ndarray          # (N, n_p + n_candidates): weighted sensitivities, base parameters first
    rw: np.ndarray          # (N,): weighted residuals
    U: np.ndarray           # orthonormal basis of the estimated parameters' columns
    estimated: list         # names of the estimated base parameters
    families: list          # (label, indices into ``estimated``, orthonormal basis) of each family
    notes: tuple


def _base_projection(fit: EstimationResult, sens) -> _Projection:
    """The weighted sensitivities and residuals, and the basis the score test projects out: the
    estimated parameters (those at a bound held fixed) or, after (7.9), the estimated directions."""
    base = fit.spec
    n_p = len(base.parameters)
    sigma = sens.sigma
    Sw = sens.S / sigma[:, None]
    rw = np.concatenate([fit.residuals[c] for c in fit.nlp.channel_names]) / sigma
    P = fit.nlp.transform.P
    free = np.ones(n_p, bool)
    notes = []
    if fit.nlp.transform.is_identity:
        for s, side in fit.active_bounds():
            free[base.parameter_symbols.index(s)] = False
            notes.append(f"{s} is at its {side} bound in the base fit: the test holds it fixed")
        X = Sw[:, :n_p][:, free]
        est_names = [n for n, f in zip(base.parameter_names, free) if f]
    else:
        X = Sw[:, :n_p] @ P
        est_names = list(base.parameter_names)
        notes.append(f"the base fit estimated {P.shape[1]} transformed directions (7.9): the test projects out "
                     "those directions only")
    Xp = Sw[:, :n_p][:, [base.parameter_names.index(n) for n in est_names]]
    fam_bases = [(label, idx, _orthonormal(Xp[:, idx])) for label, idx in _families(base, est_names)]
    return _Projection(Sw, rw, _orthonormal(X), est_names, fam_bases, tuple(notes))


class _Groups(NamedTuple):
    """Confounded groups in rank order (candidate indices, the leader first): ``group_of[i]`` the
    group of candidate ``i``, ``link[i]``
    ``(leader it joined, |cos|, score ratio)`` for a candidate that joined another's group."""

    groups: list
    group_of: dict
    link: dict


def _group_confounded(raw: Sequence[dict], order: Sequence[int]) -> _Groups:
    """Single linkage in rank order: a candidate joins the first group holding a better-ranked one
    whose output change is collinear with its own (:data:`COLLINEAR_COS`) and whose score statistic
    is close (:data:`SCORE_RATIO`)."""
    lm = np.array([r["statistic"] for r in raw])
    # |cos| between the output changes the candidates would make: one Gram matrix (no vector BLAS calls,
    # which are slow under a multi-threaded BLAS on a busy machine)
    Dm = np.column_stack([r["direction"] for r in raw])
    gram = Dm.T @ Dm
    dnorm = np.sqrt(np.clip(np.diag(gram), 0.0, None))
    groups: list[list[int]] = []
    group_of: dict[int, int] = {}
    link: dict[int, tuple[int, float, float]] = {}

    def confounded(i, j):
        if dnorm[i] == 0 or dnorm[j] == 0:
            return None
        cos = abs(float(gram[i, j]) / (dnorm[i] * dnorm[j]))
        ratio = min(lm[i], lm[j]) / max(lm[i], lm[j]) if max(lm[i], lm[j]) > 0 else 1.0
        return (j, cos, ratio) if cos >= COLLINEAR_COS and ratio >= SCORE_RATIO else None

    for i in order:
        hit = next(((g, why) for g, members in enumerate(groups) for j in members
                    for why in (confounded(i, j),) if why is not None), None)
        if hit is None:
            group_of[i] = len(groups)
            groups.append([i])
        else:
            groups[hit[0]].append(i)
            group_of[i], link[i] = hit
    return _Groups(groups, group_of, link)


def _candidate_scores(raw: Sequence[dict], order: Sequence[int], groups: _Groups, aug: AugmentedModel,
                      level: float) -> list[CandidateScore]:
    """The :class:`CandidateScore` of each candidate in rank order: Holm-corrected p-values, its
    group, and the notes (confounded, asks for a value outside its bounds)."""
    spec_a = aug.spec
    p_raw = np.array([r["p_value"] for r in raw])
    p_corr = holm(p_raw)
    scores = []
    for rank, i in enumerate(order, 1):
        r = raw[i]
        e = aug.effects[i]
        note = list(r["notes"])
        g = groups.groups[groups.group_of[i]]
        if i in groups.link:
            lead, cos, ratio = groups.link[i]
            note.append(f"confounded with {aug.effects[lead].name} (score statistics {100 * (1 - ratio):.0f} % apart, "
                        f"|cos| {cos:.3f} of the output changes): the data cannot tell them apart at this fit; "
                        "refit both (confirm) to decide")
        elif len(g) > 1:
            others = ", ".join(aug.effects[j].name for j in g[1:])
            note.append(f"leads a confounded group with {others}: refit each (confirm) to decide")
        outside = [f"{k} = {v:.3g}" for k, v in r["one_step"].items()
                   if k in spec_a.parameter_names and not (spec_a.parameter(k).lower <= v <= spec_a.parameter(k).upper)]
        if outside:
            note.append(f"the data ask for {', '.join(outside)} (one-step estimate), outside its bounds: physically "
                        "impossible, so probably another effect's signature (the statistic is two-sided)")
        scores.append(CandidateScore(
            name=e.name, title=e.title, statistic=float(r["statistic"]), dof=int(r["dof"]),
            p_value=float(p_raw[i]), p_value_corrected=float(p_corr[i]), predicted_drop=float(r["statistic"]) / 2,
            group=groups.group_of[i] + 1, absorbed_by=r["absorbed_by"], significant=bool(p_corr[i] < level),
            note="; ".join(note), kind=e.kind, parameters=aug.parameters[e.name], retained=float(r["retained"]),
            one_step=r["one_step"], rank=rank, realistic_statistic=r["realistic_statistic"]))
    return scores


def _score_one(effect: Effect, Sb: np.ndarray, Sbt: np.ndarray, rw: np.ndarray, fam_bases, base: ModelSpec,
               est_names: Sequence[str], meanings: dict) -> dict:
    """LM statistic, dof, retained share, absorption and direction of one candidate
    (``Sb`` its weighted sensitivity columns, ``Sbt`` the same projected)."""
    names = list(effect.parameter_names) or [f"{effect.name}[{j}]" for j in range(Sb.shape[1])]
    notes: list[str] = []
    norms = np.sqrt(np.einsum("ij,ij->j", Sb, Sb))
    out = {"statistic": 0.0, "dof": 0, "p_value": 1.0, "logp": 0.0, "retained": 0.0, "absorbed_by": None,
           "one_step": {}, "direction": np.zeros_like(rw), "notes": notes, "absorbed_share": 1.0,
           "realistic_statistic": None}
    if effect.realistic and len(effect.realistic) == Sb.shape[1]:
        # the most visible combination of realistic size, |beta_j| <= realistic_j: bounded by the
        # ellipsoid beta = D w, |w| <= sqrt(k), that holds that box (k parameters, D = diag(realistic))
        Dm = Sbt * np.array([abs(effect.realistic[n]) for n in names])
        out["realistic_statistic"] = float(len(names) * np.linalg.eigvalsh(_tdot(Dm, Dm))[-1])
    if not np.any(norms > 0):
        notes.append("its parameters do not change the outputs at this fit")
        return out
    live = norms > 0
    if not live.all():
        notes.append("parameter(s) " + ", ".join(n for n, l in zip(names, live) if not l)
                     + " do not change the outputs at this fit")
    A = Sb[:, live] / norms[live]                   # unit columns
    At = Sbt[:, live] / norms[live]                 # projected
    G0 = _tdot(A, A)
    G1 = _tdot(At, At)
    # generalized eigenproblem G1 w = mu G0 w: mu = retained squared share of each combination
    L = np.linalg.cholesky(G0 + 1e-14 * np.eye(G0.shape[0]))
    Li = np.linalg.inv(L)
    mu, W = np.linalg.eigh(Li @ G1 @ Li.T)
    mu = np.clip(mu, 0.0, 1.0)
    retained = float(np.sqrt(mu.max()))
    out["retained"] = retained
    keep = mu > 1e-8
    absorbed_share = 1.0 - mu.max()
    out["absorbed_share"] = float(absorbed_share)
    if absorbed_share > PARTLY_ABSORBED and fam_bases:
        best = Li.T @ W[:, np.argmax(mu)]           # least-absorbed combination (in unit-column coordinates)
        out["absorbed_by"], note = _absorption(effect, A @ best, absorbed_share, out["realistic_statistic"],
                                               fam_bases, base, est_names, meanings)
        notes.append(note)
    if not keep.any():
        return out
    # LM = g^T I^-1 g in the kept directions of the projected columns
    Wk = Li.T @ W[:, keep]                           # combinations of unit columns, G0-orthonormal
    B = At @ Wk                                      # projected, orthogonal columns with squared norms mu
    g = _tdot(B, rw)
    lam = mu[keep]
    coef = g / lam
    lm = float(np.sum(g * coef))
    dof = int(keep.sum())
    out["statistic"] = lm
    out["dof"] = dof
    out["p_value"] = float(stats.chi2.sf(lm, dof))
    out["logp"] = float(stats.chi2.logsf(lm, dof))
    out["direction"] = B @ coef                      # the output change the effect would make (weighted)
    # one-step estimate of the effect's parameters: beta = -(I^-1 g) in physical units
    step = -(Wk @ coef)
    full = np.zeros(len(names))
    full[live] = step / norms[live]
    out["one_step"] = {n: float(v) for n, v in zip(names, full)}
    return out


def _absorption(effect: Effect, a: np.ndarray, absorbed_share: float, lam: float | None, fam_bases,
                base: ModelSpec, est_names: Sequence[str], meanings: dict) -> tuple[list | None, str]:
    """Which families of estimated parameters take up an effect's least-absorbed output change
    ``a`` (weighted): ``(absorbed_by or None, note)``; absorbed beyond :data:`ABSORBED`, the note
    says whether a realistic size (score statistic ``lam``) would still be seen."""
    a = a / np.sqrt(np.einsum("i,i->", a, a))
    expl = sorted(((float(np.sum(_tdot(Q, a) ** 2)), label, idx) for label, idx, Q in fam_bases),
                  key=lambda z: -z[0])
    total = absorbed_share
    chosen = [z for z in expl if z[0] >= 0.5 * total] or [z for z in expl if z[0] >= 0.1 * total] or expl[:1]
    members = [est_names[i] for _, _, idx in chosen for i in idx]
    labels = ", ".join(label for _, label, _ in chosen)
    key = tuple(members)
    if key not in meanings:
        meanings[key] = _meaning(base, members)
    meaning = meanings[key]
    if absorbed_share <= ABSORBED:
        return None, (f"partly confounded with {labels} ({100 * absorbed_share:.0f} % of its signature): "
                      f"the base fit has distorted {meaning}")
    size = ", ".join(f"{k} = {v:.3g}" for k, v in effect.realistic.items())
    note = (f"confounded with {labels}: it would be absorbed into {meaning} (they take up "
            f"{100 * absorbed_share:.1f} % of its signature)")
    if lam is not None and lam < DETECTABLE:
        note += (f"; at a realistic size ({size}) what they cannot take up would raise the score statistic "
                 f"by only about {lam:.2g}: the effect would go unseen")
    elif lam is not None:
        note += (f"; at a realistic size ({size}) what they cannot take up is still detectable (score "
                 f"statistic about {lam:.3g}), and the base fit has distorted {meaning}")
    return members, note


# ---------------------------------------------------------------------------
# where an event shape's refits start
# ---------------------------------------------------------------------------


def scan_profile(fit: EstimationResult, bank: Effect) -> tuple[np.ndarray, np.ndarray] | None:
    """The projected columns ``Ct`` and scores ``g`` of a scan's bank at ``fit`` (one sensitivity solve; see
    :func:`onset_starts`), or None when the bank cannot be built or scored. Event shapes whose scans share a
    bank (a throttle step and a throttle window) share this."""
    try:
        aug = augment(fit, [bank])
        sens = _augmented_sensitivities(fit, aug)
    except (ModelError, RocketidError, ValueError, np.linalg.LinAlgError):
        return None
    proj = _base_projection(fit, sens)
    n_p = len(fit.spec.parameters)
    C = proj.Sw[:, n_p:]
    Ct = C - proj.U @ (proj.U.T @ C)
    return Ct, Ct.T @ proj.rw


def onset_starts(fit: EstimationResult, scan, *, n: int = 4, cap: float | None = None,
                 profile: tuple[np.ndarray, np.ndarray] | None = None) -> list[dict]:
    """Starting points of an event shape's refit at ``fit``: the best local maxima of its score profile.

    The scan's bank (:class:`~rocketid.diagnostics.effects.OnsetScan`) holds the effect's change at each of
    its onset times, every size at zero; one sensitivity solve at ``fit`` gives, for each onset time alone,
    the score statistic ``LM_k`` (projected as in :func:`rank_candidates`) and the one-step size
    ``-g_k / I_k``. The profile of ``LM_k`` over the onset time has several local maxima (an event's
    objective is not convex in its time, and a fit that absorbed the event into its coefficients puts its
    highest peak elsewhere: Halcyon-8's 150 kg released at 55 s peaks at 74 s, with a local maximum at
    54 s). The ``n`` highest local maxima are returned as ``{time: t_k, size: one-step size}``, best first,
    the size held within ``cap`` in magnitude when given and within the size's bounds; a time whose one-step
    size has a sign the bounds exclude (a mass *gained*, a drag dip for a hump) scores 0.

    ``profile``: the bank's :func:`scan_profile` at ``fit`` when already made.

    Returns
    -------
    list of dict
        Empty when the bank cannot be built or scored (the caller falls back to fixed starts).
    """
    profile = scan_profile(fit, scan.bank) if profile is None else profile
    if profile is None:
        return []
    Ct, g = profile
    if scan.end is not None:
        return _window_starts(Ct, g, scan, n, cap)
    lm, size, ok = _step_scores(Ct, g, scan)
    k = len(lm)
    peaks = [j for j in range(k) if ok[j] and (j == 0 or lm[j] >= lm[j - 1]) and (j == k - 1 or lm[j] >= lm[j + 1])]
    peaks.sort(key=lambda j: -lm[j])
    return [{scan.time: float(scan.times[j]), scan.size: _held(float(size[j]), scan, cap)} for j in peaks[:n]]


class ScanPeak(NamedTuple):
    """The highest score of a located shape's scan (:func:`scan_peak`)."""

    statistic: float
    """The score statistic (1 degree of freedom) at the best location."""
    where: tuple
    """The location: ``(onset,)`` for a step or a hump, ``(onset, end)`` for a window (the scan's unit)."""
    tested: int
    """How many locations (or pairs of them) were scored: the count a scan-wide significance test divides by."""

    @property
    def predicted_drop(self) -> float:
        """Predicted fall of the objective ``J`` (half the statistic), as :attr:`CandidateScore.predicted_drop`."""
        return 0.5 * self.statistic

    def p_value(self, n_candidates: int = 1) -> float:
        """Bonferroni p-value of the peak: over the locations scored and ``n_candidates`` candidates."""
        return float(min(1.0, stats.chi2.sf(self.statistic, 1) * self.tested * max(1, n_candidates)))


def scan_peak(scan, profile: tuple[np.ndarray, np.ndarray] | None) -> ScanPeak | None:
    """The highest score statistic of a located shape over its scan (every onset time, or every pair of
    them for a window; a location whose one-step size has a sign the bounds exclude does not count), from
    the bank's :func:`scan_profile`. None when there is no profile or nothing can be scored.

    The statistic is that of the best location *chosen after looking*: it is compared with a threshold
    corrected for the number of locations (:meth:`ScanPeak.p_value`), not with ``chi2(1)``."""
    if profile is None:
        return None
    Ct, g = profile
    k = len(g)
    if scan.end is None:
        lm, _, ok = _step_scores(Ct, g, scan)
        if not ok.any():
            return None
        j = int(np.argmax(np.where(ok, lm, -np.inf)))
        return ScanPeak(float(lm[j]), (float(scan.times[j]),), k)
    lm, _, _ = _pair_scores(Ct, g, scan)
    if not np.isfinite(lm).any():
        return None
    a, b = np.unravel_index(int(np.argmax(lm)), lm.shape)
    return ScanPeak(float(lm[a, b]), (float(scan.times[a]), float(scan.times[b])), k * (k - 1) // 2)


def _step_scores(Ct: np.ndarray, g: np.ndarray, scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(LM, one-step size, usable)`` of each onset time of a step's scan."""
    info = np.sum(Ct * Ct, axis=0)
    ok = info > 0
    size = np.where(ok, -g / np.where(ok, info, 1.0), 0.0)
    ok &= _signed(size, scan)
    lm = np.where(ok, g * g / np.where(ok, info, 1.0), 0.0)
    return lm, size, ok


def _signed(size: np.ndarray, scan) -> np.ndarray:
    """Where a one-step size has a sign the size's bounds allow (a mass released is >= 0, a drag hump >= 0):
    a peak of the score whose size points out of the bounds is no start for the shape."""
    lo, hi = scan.bounds
    return ~((lo >= 0.0) & (size <= 0.0)) & ~((hi <= 0.0) & (size >= 0.0))


def _held(a: float, scan, cap: float | None) -> float:
    """A one-step size held within ``cap`` in magnitude (when given) and within the size's bounds."""
    if cap is not None and np.isfinite(cap):
        a = float(np.clip(a, -cap, cap))
    lo, hi = scan.bounds
    return float(np.clip(a, lo, hi))


def _window_starts(Ct: np.ndarray, g: np.ndarray, scan, n: int, cap: float | None) -> list[dict]:
    """:func:`onset_starts` of a window: the score of every pair of onset times ``a < b`` (the copy at ``a``
    minus the copy at ``b``: ``(g_a - g_b)^2 / (I_aa - 2 I_ab + I_bb)``, with the projected information
    ``I = Ct' Ct``), and the ``n`` highest local maxima over the pairs (each against its up to 8 neighbours),
    as ``{time: t_a, end: t_b, size: one-step size}``."""
    lm, num, den = _pair_scores(Ct, g, scan)
    k = len(g)
    upper = np.isfinite(lm)
    padded = np.pad(lm, 1, constant_values=-np.inf)
    neigh = np.max([padded[1 + di:1 + di + k, 1 + dj:1 + dj + k] for di in (-1, 0, 1) for dj in (-1, 0, 1)
                    if (di, dj) != (0, 0)], axis=0)
    peaks = np.argwhere(upper & (lm >= neigh))
    peaks = sorted(peaks, key=lambda ij: -lm[ij[0], ij[1]])
    return [{scan.time: float(scan.times[a]), scan.end: float(scan.times[b]),
             scan.size: _held(float(-num[a, b] / den[a, b]), scan, cap)} for a, b in peaks[:n]]


def _pair_scores(Ct: np.ndarray, g: np.ndarray, scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(LM, g_a - g_b, I_aa - 2 I_ab + I_bb)`` of every pair of onset times ``a < b`` of a window's scan;
    ``LM`` is ``-inf`` where the pair is not scored (``a >= b``, no information, a size of excluded sign)."""
    info = Ct.T @ Ct
    d = np.diag(info)
    den = d[:, None] + d[None, :] - 2.0 * info
    num = g[:, None] - g[None, :]
    k = len(g)
    upper = np.triu(np.ones((k, k), bool), 1) & (den > 1e-12 * max(1.0, float(d.max(initial=0.0))))
    upper &= _signed(-num / np.where(upper, den, 1.0), scan)
    lm = np.where(upper, num * num / np.where(upper, den, 1.0), -np.inf)
    return lm, num, den
