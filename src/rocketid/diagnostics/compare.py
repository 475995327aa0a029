"""Compare: each measured channel against the model, with fit statistics.

The first step of the diagnosis loop (compare, locate, rank, add, refit).
For every channel of an :class:`~rocketid.solve.EstimationResult` the
measured values are set against the model's prediction, and the residuals,
divided by the channel's noise sigma, are tested for what a correct model
leaves behind: white Gaussian noise of unit variance.

Notation
--------
==============  ================================================================
``r_i``         residual, model minus measurement (rocketid's sign everywhere)
``e_i``         normalized residual ``r_i / sigma``; N(0, 1) for a correct model
``n``           samples of the channel; ``N`` over all channels
``p``           estimated quantities of the fit (``fit.n_estimated``)
``chi2/dof``    ``sum(e^2) / (n - p n / N)``: the estimated quantities' degrees of
                freedom are shared among channels in proportion to their samples
``U``           Theil's inequality coefficient
                ``sqrt(mean(r^2)) / (sqrt(mean(yhat^2)) + sqrt(mean(y^2)))``, 0 for
                a perfect fit, 1 for no agreement; its proportions ``U_M`` (bias),
                ``U_S`` (variance) and ``U_C`` (covariance) sum to 1
``rho_k``       autocorrelation of ``e`` at lag ``k`` (about its mean)
``Q``           Ljung-Box ``n (n + 2) sum_{k=1..h} rho_k^2 / (n - k)``, chi2(h)
                for white residuals
``JB``          Jarque-Bera ``n/6 (S^2 + (K - 3)^2 / 4)``, chi2(2) for Gaussian
                residuals (``scipy.stats.jarque_bera``)
``eta``         the statistic criterion (7.10) over all channels, with its four
                terms (``rocketid.sampling.criterion``)
==============  ================================================================

eta (7.10) measures skewness and kurtosis, not whiteness: a slow drift that
is symmetric about zero leaves eta small. The Ljung-Box test beside it is the
whiteness test; the windowed statistics of :mod:`rocketid.diagnostics.locate`
say where the residuals fail.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..errors import DataError, SettingsError
from ..output import new_axes, plot_target, save_figure
from ..solve import EstimationResult
from ..summary import Section, Summary, SummaryText, Table

__all__ = ["LjungBox", "Normality", "Theil", "ChannelComparison", "Comparison", "compare", "ljung_box",
           "normality", "theil", "criterion_terms", "DEFAULT_LAGS"]

#: Lags of the Ljung-Box test (0.2 s at 100 Hz), fewer for short channels (n // 5).
DEFAULT_LAGS = 20
#: chi2/dof above which the comparison calls the misfit gross (a wrong model, input or unit).
GROSS_MISMATCH = 1000.0
#: Two-sided share of N(0, 1) outside +-2: what a correct model leaves outside the band.
EXPECTED_OUTSIDE_2SIGMA = 0.04550026


# ---------------------------------------------------------------------------
# Tests on one residual series
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class LjungBox:
    """The Ljung-Box whiteness test of a residual series.

    Attributes
    ----------
    statistic : float
        ``Q = n (n + 2) sum_{k=1..h} rho_k^2 / (n - k)``.
    dof : int
        ``h``, the number of lags (no fitted ARMA terms).
    p_value : float
        ``P(chi2(h) > Q)``; small means the residuals are not white.
    autocorrelation : ndarray, shape (h + 1,)
        ``rho_0 = 1, rho_1 .. rho_h``.
    """

    statistic: float
    dof: int
    p_value: float
    autocorrelation: np.ndarray

    @property
    def lags(self) -> int:
        return self.dof

    @property
    def lag1(self) -> float:
        """Lag-1 autocorrelation (``+-2/sqrt(n)`` for white noise)."""
        return float(self.autocorrelation[1]) if self.autocorrelation.size > 1 else math.nan


def autocorrelation(e: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation ``rho_0..rho_lags`` of ``e`` about its mean (biased, ``1/n``)."""
    e = np.asarray(e, float).ravel()
    d = e - e.mean()
    c0 = float(d @ d)
    n = d.size
    if c0 == 0:
        return np.concatenate([[1.0], np.zeros(lags)])
    # FFT autocovariance (n up to 10^5 or more)
    m = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfft(d, m)
    acov = np.fft.irfft(f * np.conj(f), m)[: lags + 1]
    return acov / c0


def ljung_box(e: np.ndarray, lags: int | None = None) -> LjungBox:
    """The Ljung-Box test (chi-square p-value from ``scipy.stats.chi2``).

    Parameters
    ----------
    e : array, shape (n,)
        Residuals (normalized or not: the test is scale free).
    lags : int, optional
        ``h`` (default :data:`DEFAULT_LAGS`, at most ``n // 5``).

    Raises
    ------
    DataError
        Fewer than 10 samples, or ``lags`` not in 1 .. n - 1.
    """
    from scipy.stats import chi2

    e = np.asarray(e, float).ravel()
    n = e.size
    if n < 10:
        raise DataError(f"the Ljung-Box test needs at least 10 residuals, got {n}")
    h = min(DEFAULT_LAGS, max(1, n // 5)) if lags is None else int(lags)
    if not 1 <= h < n:
        raise DataError(f"Ljung-Box lags must be in 1 .. {n - 1} for {n} residuals, got {lags}")
    rho = autocorrelation(e, h)
    k = np.arange(1, h + 1)
    q = float(n * (n + 2) * np.sum(rho[1:] ** 2 / (n - k)))
    return LjungBox(q, h, float(chi2.sf(q, h)), rho)


@dataclass(frozen=True)
class Normality:
    """Normality of a residual series: Jarque-Bera with its moments.

    Attributes
    ----------
    statistic : float
        ``JB = n/6 (S^2 + (K - 3)^2 / 4)`` (``scipy.stats.jarque_bera``).
    p_value : float
        ``P(chi2(2) > JB)``.
    skewness, kurtosis : float
        Sample moments ``S`` and ``K`` (central, ``1/n``; ``K = 3`` for a Gaussian).
    """

    statistic: float
    p_value: float
    skewness: float
    kurtosis: float


def normality(e: np.ndarray) -> Normality:
    """The Jarque-Bera test of ``e`` (``scipy.stats.jarque_bera``) with skewness and kurtosis."""
    from scipy.stats import jarque_bera

    e = np.asarray(e, float).ravel()
    if e.size < 8:
        raise DataError(f"the normality test needs at least 8 residuals, got {e.size}")
    res = jarque_bera(e)
    d = e - e.mean()
    z2 = float(np.mean(d ** 2))
    s = float(np.mean(d ** 3) / z2 ** 1.5) if z2 > 0 else math.nan
    k = float(np.mean(d ** 4) / z2 ** 2) if z2 > 0 else math.nan
    return Normality(float(res.statistic), float(res.pvalue), s, k)


@dataclass(frozen=True)
class Theil:
    """Theil's inequality coefficient and its proportions.

    Attributes
    ----------
    U : float
        ``sqrt(mean(r^2)) / (sqrt(mean(yhat^2)) + sqrt(mean(y^2)))``.
    bias, variance, covariance : float
        ``U_M = (mean yhat - mean y)^2 / MSE``, ``U_S = (s_yhat - s_y)^2 / MSE``,
        ``U_C = 2 (1 - corr) s_yhat s_y / MSE``; they sum to 1. A good model
        puts the error in ``U_C`` (unsystematic); a large ``U_M`` or ``U_S``
        is a systematic error.
    """

    U: float
    bias: float
    variance: float
    covariance: float


def theil(predicted: np.ndarray, measured: np.ndarray) -> Theil:
    """Theil's inequality coefficient of a prediction against measurements."""
    yp = np.asarray(predicted, float).ravel()
    ym = np.asarray(measured, float).ravel()
    r = yp - ym
    mse = float(np.mean(r ** 2))
    den = math.sqrt(float(np.mean(yp ** 2))) + math.sqrt(float(np.mean(ym ** 2)))
    U = math.sqrt(mse) / den if den > 0 else math.nan
    if mse == 0:
        return Theil(U, 0.0, 0.0, 1.0)
    sp_, sm = float(np.std(yp)), float(np.std(ym))
    corr = float(np.corrcoef(yp, ym)[0, 1]) if sp_ > 0 and sm > 0 else 0.0
    um = (float(yp.mean()) - float(ym.mean())) ** 2 / mse
    us = (sp_ - sm) ** 2 / mse
    uc = 2 * (1 - corr) * sp_ * sm / mse
    return Theil(U, um, us, uc)


# ---------------------------------------------------------------------------
# eta (7.10)
# ---------------------------------------------------------------------------


def criterion_terms(residuals: Mapping[str, np.ndarray], sigma: Mapping[str, float]) -> tuple[dict, str]:
    """eta (7.10) and its terms over all channels, each divided by its sigma, computed by
    :func:`rocketid.sampling.criterion.statistic_criterion` (the one implementation).

    Returns ``({"eta", "|s1|", "|k1-3|", "|s1-s2|", "|k1-k2|", "s1", "k1", "s2", "k2"}, source)``.
    """
    from ..sampling.criterion import statistic_criterion
    return statistic_criterion(dict(residuals), dict(sigma)).as_dict(), "rocketid.sampling.criterion"


# ---------------------------------------------------------------------------
# Per channel and overall
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ChannelComparison:
    """One channel: measured, model, residuals and their statistics.

    Attributes
    ----------
    name : str
    times, measured, predicted : ndarray, shape (n,)
    sigma : float
        The noise standard deviation the fit used.
    residual : ndarray, shape (n,)
        ``predicted - measured``.
    normalized : ndarray, shape (n,)
        ``residual / sigma``.
    rms, bias, std : float
        Of ``residual`` (channel units).
    chi2_per_dof : float
        ``sum(e^2) / (n - p n / N)`` (see the module notation).
    theil : Theil
    outside_2sigma : float
        Share of ``|e| > 2`` (0.0455 expected).
    whiteness : LjungBox
    normality : Normality
    """

    name: str
    times: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    sigma: float
    residual: np.ndarray
    normalized: np.ndarray
    rms: float
    bias: float
    std: float
    chi2_per_dof: float
    theil: Theil
    outside_2sigma: float
    whiteness: LjungBox
    normality: Normality

    @property
    def n(self) -> int:
        return int(self.times.size)

    @property
    def bias_z(self) -> float:
        """``mean(e) sqrt(n)``: the bias in standard errors of a white-noise mean."""
        return float(np.mean(self.normalized) * math.sqrt(self.n))

    def to_dict(self) -> dict:
        return {"name": self.name, "n": self.n, "sigma": self.sigma, "rms": self.rms, "bias": self.bias,
                "std": self.std, "bias_z": self.bias_z, "chi2_per_dof": self.chi2_per_dof,
                "theil": {"U": self.theil.U, "bias": self.theil.bias, "variance": self.theil.variance,
                          "covariance": self.theil.covariance},
                "outside_2sigma": self.outside_2sigma,
                "ljung_box": {"statistic": self.whiteness.statistic, "dof": self.whiteness.dof,
                              "p_value": self.whiteness.p_value, "lag1": self.whiteness.lag1},
                "jarque_bera": {"statistic": self.normality.statistic, "p_value": self.normality.p_value,
                                "skewness": self.normality.skewness, "kurtosis": self.normality.kurtosis}}


@dataclass(frozen=True)
class Comparison:
    """Every channel against the model, and the statistics over all channels.

    Attributes
    ----------
    model : str
    channels : tuple of ChannelComparison
    chi2_per_dof : float
        The fit's ``2 J / (N - p)``.
    n_data, n_estimated : int
    criterion : dict
        eta (7.10), its four terms and the moments (see :func:`criterion_terms`).
    criterion_source : str
        Which implementation computed eta.
    whiteness : LjungBox
        Of all channels' normalized residuals, each channel tested separately
        and the statistics added (``Q`` and ``h`` sum over channels).
    level : float
        Significance level of the verdicts.
    notes : tuple of str
    predicted_only : tuple
        ``(output name, times, values)`` of each model output the data do not measure: the
        fitted model's prediction at the mesh nodes (plotted, not tested).
    """

    model: str
    channels: tuple
    chi2_per_dof: float
    n_data: int
    n_estimated: int
    criterion: dict
    criterion_source: str
    whiteness: LjungBox
    level: float = 0.05
    notes: tuple = ()
    predicted_only: tuple = ()

    def __getitem__(self, name: str) -> ChannelComparison:
        for c in self.channels:
            if c.name == name:
                return c
        raise DataError(f"no channel named {name!r}; the comparison has {', '.join(self.names)}")

    @property
    def names(self) -> tuple:
        return tuple(c.name for c in self.channels)

    @property
    def eta(self) -> float:
        return float(self.criterion["eta"])

    @property
    def fits_to_noise(self) -> bool:
        """chi2/dof within its 99.9 % band for white noise and every channel white at ``level``
        (Bonferroni over channels)."""
        from scipy.stats import chi2

        dof = max(1, self.n_data - self.n_estimated)
        hi = chi2.isf(0.001, dof) / dof
        white = all(c.whiteness.p_value >= self.level / len(self.channels) for c in self.channels)
        return bool(self.chi2_per_dof <= hi and white)

    def channel_table(self) -> Table:
        """One row per channel: its statistics (the summary's table)."""
        return Table(("channel", "n", "sigma", "RMS", "bias", "bias z", "chi2/dof", "Theil U", "U_M", "|e|>2 (%)",
                      "LB p", "rho1", "JB p"),
                     [(c.name, c.n, c.sigma, c.rms, c.bias, c.bias_z, c.chi2_per_dof, c.theil.U, c.theil.bias,
                       100 * c.outside_2sigma, c.whiteness.p_value, c.whiteness.lag1, c.normality.p_value)
                      for c in self.channels],
                     (None, None, ".3g", ".4g", ".3g", ".3g", ".4g", ".2e", ".2f", ".1f", ".2g", ".3f", ".2g"))

    def table(self) -> str:
        """One line per channel (:meth:`channel_table` as text)."""
        return "\n".join("  " + line for line in self.channel_table().text_lines())

    def summary(self) -> SummaryText:
        """Fixed sections (overall, channels, eta) and numbered notes: a
        :class:`~rocketid.summary.Summary`, as its text (:class:`~rocketid.summary.SummaryText`)."""
        crit = self.criterion
        overall = Section("Overall", (
            ("chi2 / dof", f"{self.chi2_per_dof:.4f}  ({self.n_data} values, {self.n_estimated} estimated)"),
            ("white noise", f"{'yes' if self.fits_to_noise else 'NO'} (chi2/dof band and Ljung-Box at level "
                            f"{self.level:g})")))
        channels = Section("Channels (residual = model - measured; e = residual / sigma)", (self.channel_table(),))
        eta = Section("Statistic criterion (7.10)", (
            ("eta", f"{crit['eta']:.4g} = |s1| {crit['|s1|']:.3g} + |k1-3| {crit['|k1-3|']:.3g} "
                    f"+ |s1-s2| {crit['|s1-s2|']:.3g} + |k1-k2| {crit['|k1-k2|']:.3g}"),
            ("moments", f"s1 {crit['s1']:.3g}, k1 {crit['k1']:.4g}, s2 {crit['s2']:.3g}, k2 {crit['k2']:.4g}"),
            ("computed by", self.criterion_source)))
        return SummaryText(Summary(f"rocketid comparison: {self.model}", (overall, channels, eta), self.notes))

    def to_dict(self) -> dict:
        return {"model": self.model, "chi2_per_dof": self.chi2_per_dof, "n_data": self.n_data,
                "n_estimated": self.n_estimated, "fits_to_noise": self.fits_to_noise,
                "criterion": {k: float(v) for k, v in self.criterion.items()},
                "criterion_source": self.criterion_source,
                "channels": [c.to_dict() for c in self.channels], "notes": list(self.notes),
                "predicted_only": [name for name, _, _ in self.predicted_only]}

    # ---- plots
    def plot(self, axes=None, *, path=None, title: str | None = None):
        """Per channel: measured and model against time (left), normalized residual
        against time with the +-2 sigma band and a 1 s running mean (right); a row for each
        output the data do not measure (its prediction).

        Parameters
        ----------
        axes : array of matplotlib Axes, shape (n_rows, 2), optional
            Default: a new figure's, outside pyplot (no backend is touched).
        path : str or path, optional
            Save the figure there (``plot("compare.png")`` works too).
        title : str, optional

        Returns
        -------
        ndarray of matplotlib Axes, shape (n_rows, 2)
        """
        axes, path = plot_target(axes, path)
        n = len(self.channels) + len(self.predicted_only)
        own = axes is None
        if own:
            axes = new_axes((11, 2.5 * n + 0.6), n, 2, squeeze=False, gridspec_kw={"width_ratios": [1, 1.4]})
        axes = np.asarray(axes, dtype=object)
        if axes.size != 2 * n:
            raise SettingsError(f"Comparison.plot draws {n} rows of 2 panels; it got {axes.size} axes")
        axes = axes.reshape(n, 2)
        for (a1, a2), (name, t, y) in zip(axes[len(self.channels):], self.predicted_only):
            a1.plot(t, y, "-", lw=1.2, color="tab:blue", label="model (not measured)")
            a1.set_ylabel(name)
            a1.legend(loc="upper left", fontsize=8, frameon=False)
            a2.axis("off")
            a2.text(0.02, 0.5, f"{name} is not measured: predicted, not fitted", transform=a2.transAxes, fontsize=9)
        for (a1, a2), c in zip(axes, self.channels):
            k = _stride(c.n)
            a1.plot(c.times[::k], c.measured[::k], ".", ms=1.5, color="0.55", label="measured", rasterized=True)
            a1.plot(c.times, c.predicted, "-", lw=1.2, color="tab:blue", label="model")
            a1.set_ylabel(c.name)
            a1.legend(loc="upper left", fontsize=8, frameon=False)
            residual_panel(a2, c.times, c.normalized)
            a2.set_ylabel(f"{c.name}: e = r / {c.sigma:g}")
            a2.set_title(f"RMS {c.rms:.3g}, bias {c.bias:+.3g}, chi2/dof {c.chi2_per_dof:.3g}, "
                         f"LB p {c.whiteness.p_value:.2g}", fontsize=9)
        axes[-1, 0].set_xlabel("t (s)")
        axes[-1, 1].set_xlabel("t (s)")
        fig = axes[0, 0].figure
        if own or title:
            fig.suptitle(title or f"{self.model}: measured vs model, normalized residuals (chi2/dof "
                                  f"{self.chi2_per_dof:.3g}, eta {self.eta:.3g})", fontsize=11)
        if own:
            fig.tight_layout()
        if path is not None:
            save_figure(fig, path, dpi=110)
        return axes

    def plot_autocorrelation(self, ax=None, *, path=None, max_lag: float = 5.0):
        """Autocorrelation of each channel's normalized residuals against the lag in
        seconds (up to ``max_lag`` s, at most a quarter of the samples), with the
        +-2/sqrt(n) band of white noise; the Ljung-Box lags are marked.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Default: a new figure's, outside pyplot.
        path : str or path, optional
            Save the figure there.

        Returns
        -------
        matplotlib Axes
        """
        ax, path = plot_target(ax, path)
        own = ax is None
        ax = new_axes((7, 3.2)) if own else ax
        for c in self.channels:
            dt = float(np.median(np.diff(c.times))) if c.n > 1 else 1.0
            k = int(max(c.whiteness.dof, min(c.n // 4, round(max_lag / dt))))
            rho = autocorrelation(c.normalized, k)
            ax.plot(np.arange(k + 1) * dt, rho, "-", lw=1.3, label=f"{c.name} (LB p {c.whiteness.p_value:.2g})")
        band = 2 / math.sqrt(min(c.n for c in self.channels))
        ax.axhspan(-band, band, color="0.8", zorder=0, label="+-2/sqrt(n)")
        lb = max(c.whiteness.dof * float(np.median(np.diff(c.times))) for c in self.channels if c.n > 1)
        ax.axvline(lb, color="0.5", ls=":", lw=0.8, label="Ljung-Box lags")
        ax.set_xlabel("lag (s)")
        ax.set_ylabel("autocorrelation of e")
        ax.set_ylim(min(-0.2, ax.get_ylim()[0]), 1.02)
        ax.legend(fontsize=8)
        if own:
            ax.figure.tight_layout()
        if path is not None:
            save_figure(ax.figure, path, dpi=110)
        return ax


#: Most samples a scatter plot draws per channel (every k-th sample beyond; statistics use all).
PLOT_POINTS = 2500


def _stride(n: int) -> int:
    return max(1, int(math.ceil(n / PLOT_POINTS)))


def running_mean(times: np.ndarray, e: np.ndarray, width: float) -> np.ndarray:
    """Centred running mean of ``e`` over ``width`` seconds (by sample count at the median step)."""
    if times.size < 3:
        return np.asarray(e, float)
    dt = float(np.median(np.diff(times)))
    k = max(1, int(round(width / dt)))
    k = min(k, e.size)
    c = np.convolve(e, np.ones(k) / k, mode="same")
    # the edges average fewer samples
    norm = np.convolve(np.ones(e.size), np.ones(k) / k, mode="same")
    return c / norm


def residual_panel(ax, times: np.ndarray, e: np.ndarray, *, width: float = 1.0, label: str | None = None,
                   color: str = "tab:blue") -> None:
    """Normalized residuals against time, the +-2 band, and a running mean."""
    ax.axhspan(-2, 2, color="tab:green", alpha=0.12, lw=0, label="+-2 sigma")
    ax.axhline(0, color="0.4", lw=0.6)
    k = _stride(e.size)
    ax.plot(times[::k], e[::k], ".", ms=1.2, color="0.5", alpha=0.6, rasterized=True)
    ax.plot(times, running_mean(times, e, width), "-", lw=1.3, color=color,
            label=label or f"{width:g} s running mean")
    lim = max(4.0, float(np.percentile(np.abs(e), 99.5)) * 1.1)
    ax.set_ylim(-lim, lim)
    ax.legend(loc="upper right", fontsize=7, frameon=False)


# ---------------------------------------------------------------------------
# The entry point
# ---------------------------------------------------------------------------


def compare(fit: EstimationResult, *, lags: int | None = None, level: float = 0.05) -> Comparison:
    """Compare each measured channel of ``fit`` with the model (item 2 of the diagnosis).

    Parameters
    ----------
    fit : EstimationResult
    lags : int, optional
        Lags of the Ljung-Box test (default :data:`DEFAULT_LAGS`, at most n // 5).
    level : float
        Significance level of the verdicts and notes.

    Returns
    -------
    Comparison

    Raises
    ------
    SettingsError
        ``level`` not in (0, 1).
    DataError
        A channel with fewer than 10 samples.
    """
    if not isinstance(fit, EstimationResult):
        raise SettingsError(f"compare() needs an EstimationResult (rocketid.estimate), got {type(fit).__name__}")
    if not 0 < level < 1:
        raise SettingsError(f"level must be in (0, 1), got {level}")
    from scipy.stats import chi2

    nlp = fit.nlp
    sig = dict(zip(nlp.channel_names, (float(s) for s in nlp.channel_sigmas)))
    chans = [_channel_comparison(fit, name, sig[name], lags) for name in nlp.channel_names]
    # eta with each sample's own sigma (per-sample sigmas included), as the sampling's criterion computes it
    crit, source = criterion_terms(fit.residuals, nlp.channel_sigma_arrays())
    q = sum(c.whiteness.statistic for c in chans)
    h = sum(c.whiteness.dof for c in chans)
    pooled = LjungBox(q, h, float(chi2.sf(q, h)), np.mean([c.whiteness.autocorrelation for c in chans], axis=0)
                      if len({c.whiteness.dof for c in chans}) == 1 else chans[0].whiteness.autocorrelation)
    predicted = tuple((name, np.asarray(fit.node_times, float), np.asarray(fit.predict(name), float))
                      for name in fit.unmeasured_outputs)
    notes = _comparison_notes(fit, chans, crit, predicted, level)
    return Comparison(model=fit.spec.name, channels=tuple(chans), chi2_per_dof=float(fit.chi2_per_dof),
                      n_data=int(fit.n_data), n_estimated=int(fit.n_estimated), criterion=crit,
                      criterion_source=source, whiteness=pooled, level=float(level), notes=tuple(notes),
                      predicted_only=predicted)


def _channel_comparison(fit: EstimationResult, name: str, sigma: float, lags: int | None) -> ChannelComparison:
    """One channel of ``fit`` against its measurements, with its statistics."""
    N, p = fit.n_data, fit.n_estimated
    ch = fit.prepared.measurements[name]
    r = np.asarray(fit.residuals[name], float)
    yhat = np.asarray(fit.predictions[name], float)
    e = np.asarray(fit.normalized_residuals[name], float)     # r / sigma_i, each sample's own sigma
    n = e.size
    dof = max(1.0, n - p * n / N)
    return ChannelComparison(
        name=name, times=np.asarray(ch.times), measured=np.asarray(ch.values), predicted=yhat, sigma=sigma,
        residual=r, normalized=e, rms=float(np.sqrt(np.mean(r ** 2))), bias=float(np.mean(r)),
        std=float(np.std(r)), chi2_per_dof=float(e @ e / dof), theil=theil(yhat, ch.values),
        outside_2sigma=float(np.mean(np.abs(e) > 2)), whiteness=ljung_box(e, lags), normality=normality(e))


def _comparison_notes(fit: EstimationResult, chans: list, crit: dict, predicted: tuple, level: float) -> list[str]:
    """The comparison's notes: convergence, chi2/dof against its band, each channel's failed tests
    (Bonferroni over channels), outputs predicted but not measured, eta small on coloured residuals."""
    from scipy.stats import chi2

    notes = []
    dof = max(1, fit.n_data - fit.n_estimated)
    hi = chi2.isf(0.001, dof) / dof
    if not fit.success:
        notes.append(f"the fit did not converge ({fit.message}): these statistics describe the last iterate")
    if fit.chi2_per_dof > hi:
        notes.append(f"chi2/dof = {fit.chi2_per_dof:.3g} is above {hi:.3f}, the 99.9 % bound for white noise with the "
                     "stated sigma: the model does not fit to the noise level")
        if fit.chi2_per_dof > GROSS_MISMATCH:
            notes.append(f"chi2/dof above {GROSS_MISMATCH:g} is a gross mismatch rather than a small missing effect: "
                         "check that the model is the vehicle's (its inputs, constants, units) and the sigma of each "
                         "channel before ranking effects")
    elif fit.chi2_per_dof < chi2.ppf(0.001, dof) / dof:
        notes.append(f"chi2/dof = {fit.chi2_per_dof:.3g} is below 1: the stated sigma is larger than the residuals' "
                     "scatter (check the sigma of each channel)")
    m = len(chans)
    for c in chans:
        bits = []
        if c.whiteness.p_value < level / m:
            bits.append(f"not white (Ljung-Box p = {c.whiteness.p_value:.2g}, lag-1 autocorrelation "
                        f"{c.whiteness.lag1:.2f})")
        if abs(c.bias_z) > 3.5:
            bits.append(f"biased (mean residual {c.bias:+.3g} = {c.bias_z:+.1f} standard errors)")
        if c.theil.bias + c.theil.variance > 0.5:
            bits.append(f"systematic (Theil proportions U_M {c.theil.bias:.2f}, U_S {c.theil.variance:.2f})")
        if c.normality.p_value < level / m:
            bits.append(f"not Gaussian (Jarque-Bera p = {c.normality.p_value:.2g}, skewness "
                        f"{c.normality.skewness:.2f}, kurtosis {c.normality.kurtosis:.2f})")
        if bits:
            notes.append(f"channel {c.name} residuals are " + "; ".join(bits))
    if predicted:
        notes.append(f"output(s) {', '.join(n for n, _, _ in predicted)} are not in the data: predicted (plotted), "
                     "not fitted")
    if crit["eta"] < 0.1 and any(c.whiteness.p_value < level / m for c in chans):
        notes.append(f"eta = {crit['eta']:.3g} is small although the residuals are not white: eta (7.10) tests "
                     "skewness and kurtosis, not whiteness")
    return notes
