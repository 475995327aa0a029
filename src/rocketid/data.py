"""Measured trajectory data: channels of samples, CSV input and output.

A :class:`Measurements` value holds one :class:`Channel` per measured output
(``x``, ``h``, ``v`` for RA-66), each with its own sample times. It is
validated when made: times finite, strictly increasing, no NaN, sigma
positive. CSV files have a header row; the time column is ``t`` and channel
columns are named like the model's outputs unless mapped otherwise.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .errors import DataError
from .output import write_csv

__all__ = ["Channel", "Measurements", "equivalent_sigma", "read_csv", "read_channels", "sigma_request", "quantization_step",
           "resolve_quantized", "QUANTIZED", "ESTIMATE", "MAX_VALUE", "SIGMA_RANGE", "difference_noise",
           "DIFFERENCE_ORDER"]

#: The word that asks for a channel's noise level to be estimated (``sigma="estimate"``,
#: ``sigma={"h": "estimate"}``, ``--sigma estimate``, ``--sigma h=estimate``).
ESTIMATE = "estimate"
#: The word that asks for a channel's sigma from its quantization step, ``q / sqrt(12)``
#: (``"quantized"``: the step found in the data; ``"quantized:0.2778"``: the step given).
QUANTIZED = "quantized"

#: Largest magnitude of a measured value: squares of larger values overflow a double.
MAX_VALUE = 1e150
#: Noise standard deviations whose weight 1/sigma^2 is a normal, finite double.
SIGMA_RANGE = (1e-150, 1e150)


@dataclass(frozen=True)
class Channel:
    """One measured output.

    Attributes
    ----------
    name : str
        The model output it measures.
    times : ndarray, shape (n,)
        Sample times, strictly increasing.
    values : ndarray, shape (n,)
    sigma : float, ndarray of shape (n,), or None
        Noise standard deviation: one for the channel, one per sample (read-only array), or
        None ("use the model's"). Per-sample sigmas weight each residual by ``1/sigma_i^2``.
    """

    name: str
    times: np.ndarray
    values: np.ndarray
    sigma: float | np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.times, dtype=float).ravel()
        y = np.asarray(self.values, dtype=float).ravel()
        if t.shape != y.shape:
            raise DataError(f"channel {self.name!r}: {t.size} times but {y.size} values")
        if t.size == 0:
            raise DataError(f"channel {self.name!r} has no samples")
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise DataError(f"channel {self.name!r}: time is NaN or infinite at sample {bad[0]} "
                            f"(and {bad.size - 1} more); remove or fix those rows")
        bad = np.flatnonzero(~np.isfinite(y))
        if bad.size:
            raise DataError(f"channel {self.name!r}: value is NaN or infinite at t = {t[bad[0]]:g} "
                            f"(sample {bad[0]}, {bad.size} in all); remove those rows or fill them")
        bad = np.flatnonzero(np.abs(y) > MAX_VALUE)
        if bad.size:
            raise DataError(f"channel {self.name!r}: value {y[bad[0]]:g} at t = {t[bad[0]]:g} is out of scale "
                            f"(|value| > {MAX_VALUE:g}: its square overflows in a least-squares fit); check the "
                            "units of the data")
        dt = np.diff(t)
        if np.any(dt == 0):
            i = int(np.flatnonzero(dt == 0)[0])
            raise DataError(f"channel {self.name!r}: duplicate time t = {t[i]:g} (samples {i} and {i + 1}); "
                            "each sample time may appear once")
        if np.any(dt < 0):
            i = int(np.flatnonzero(dt < 0)[0])
            raise DataError(f"channel {self.name!r}: times are not sorted (t = {t[i]:g} is followed by "
                            f"{t[i + 1]:g} at sample {i + 1}); sort the data by time")
        if self.sigma is not None and np.ndim(self.sigma) > 0:
            object.__setattr__(self, "sigma", _per_sample_sigma(self.name, self.sigma, t))
        elif self.sigma is not None:
            try:
                sigma = float(self.sigma)
            except (TypeError, ValueError):
                raise DataError(f"channel {self.name!r}: sigma must be a number, got {self.sigma!r}") from None
            if not (sigma > 0 and math.isfinite(sigma)):
                raise DataError(f"channel {self.name!r}: sigma must be positive and finite, got {self.sigma}")
            if not (SIGMA_RANGE[0] <= sigma <= SIGMA_RANGE[1]):
                raise DataError(f"channel {self.name!r}: sigma = {sigma:g} is out of scale (the weight 1/sigma^2 "
                                f"must be a finite positive number: {SIGMA_RANGE[0]:g} <= sigma <= "
                                f"{SIGMA_RANGE[1]:g}); check its units")
            object.__setattr__(self, "sigma", sigma)
        t.flags.writeable = False
        y.flags.writeable = False
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", y)


    @property
    def per_sample(self) -> bool:
        """True when the channel has one sigma per sample (an array), not one for all."""
        return isinstance(self.sigma, np.ndarray)

    def sigma_array(self, default: float | None = None) -> np.ndarray:
        """The noise standard deviation at every sample, shape (n,): the per-sample values, or
        the channel's one sigma (``default`` when it has none) repeated.

        Raises
        ------
        DataError
            The channel has no sigma and no ``default`` is given.
        """
        if self.per_sample:
            return self.sigma
        s = self.sigma if self.sigma is not None else default
        if s is None:
            raise DataError(f"channel {self.name!r} has no sigma; give one (sigma=, --sigma {self.name}=VALUE)")
        return np.full(self.times.size, float(s))

    def select(self, keep: np.ndarray) -> "Channel":
        """The samples where ``keep`` (a boolean mask or indices) holds, with their sigmas."""
        sigma = self.sigma[keep] if self.per_sample else self.sigma
        return Channel(self.name, self.times[keep], self.values[keep], sigma)


def equivalent_sigma(sigma: np.ndarray) -> float:
    """The one sigma with the same total weight as per-sample sigmas, ``1 / sqrt(mean(1 / sigma^2))``:
    what a channel with per-sample sigmas reports where one number per channel is expected."""
    sigma = np.asarray(sigma, float)
    return float(1.0 / np.sqrt(np.mean(1.0 / sigma ** 2)))


def _per_sample_sigma(name: str, sigma, times: np.ndarray) -> np.ndarray:
    """Check and freeze the per-sample sigmas of channel ``name`` (one per sample time)."""
    try:
        s = np.array(sigma, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"channel {name!r}: per-sample sigma must be numbers, got {type(sigma).__name__}") from None
    if s.size != times.size:
        raise DataError(f"channel {name!r}: {s.size} per-sample sigmas for {times.size} samples; give one sigma per "
                        "sample (or one number for the channel)")
    bad = np.flatnonzero(~(np.isfinite(s) & (s > 0)))
    if bad.size:
        i = int(bad[0])
        raise DataError(f"channel {name!r}: per-sample sigma {s[i]:g} at t = {times[i]:g} (sample {i}; {bad.size} "
                        "bad in all) is not positive and finite; every sample's sigma must be a positive number")
    bad = np.flatnonzero((s < SIGMA_RANGE[0]) | (s > SIGMA_RANGE[1]))
    if bad.size:
        i = int(bad[0])
        raise DataError(f"channel {name!r}: per-sample sigma {s[i]:g} at t = {times[i]:g} is out of scale (the weight "
                        f"1/sigma^2 must be a finite positive number: {SIGMA_RANGE[0]:g} <= sigma <= "
                        f"{SIGMA_RANGE[1]:g}); check its units")
    s.flags.writeable = False
    return s


@dataclass(frozen=True)
class Measurements:
    """Measured outputs, one :class:`Channel` each.

    Examples
    --------
    >>> import numpy as np
    >>> m = Measurements.from_arrays(np.array([0.1, 0.2]), {"x": [1.0, 2.0]})
    >>> m["x"].values
    array([1., 2.])
    """

    channels: tuple[Channel, ...]

    def __post_init__(self):
        names = [c.name for c in self.channels]
        if len(set(names)) != len(names):
            raise DataError(f"duplicate channel names in {names}")
        if not names:
            raise DataError("measurements have no channels")

    @classmethod
    def from_arrays(cls, t: Sequence[float], values: Mapping[str, Sequence[float]],
                    sigma: Mapping[str, float] | None = None) -> "Measurements":
        """Channels sharing the sample times ``t``."""
        sigma = dict(sigma or {})
        unknown = [k for k in sigma if k not in values]
        if unknown:
            raise DataError(f"sigma is given for {', '.join(map(repr, unknown))}, which is not a channel; "
                            f"the channels are {', '.join(map(str, values))}")
        return cls(tuple(Channel(str(k), np.asarray(t, float), np.asarray(v, float), sigma.get(k))
                         for k, v in values.items()))

    def __getitem__(self, name: str) -> Channel:
        for c in self.channels:
            if c.name == name:
                return c
        raise DataError(f"no channel named {name!r}; the data have {', '.join(self.names)}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    @property
    def n_samples(self) -> int:
        """Total number of measured values over all channels."""
        return sum(c.times.size for c in self.channels)

    def with_sigma(self, sigma: Mapping[str, float]) -> "Measurements":
        """A copy whose named channels have the noise standard deviations ``sigma`` (a number,
        or one per sample).

        Raises
        ------
        DataError
            A name that is not a channel, or a sigma that is not positive and finite.
        """
        sigma = dict(sigma)
        unknown = [k for k in sigma if k not in self.names]
        if unknown:
            raise DataError(f"sigma is given for {', '.join(map(repr, unknown))}, which is not a channel; "
                            f"the channels are {', '.join(self.names)}")
        return Measurements(tuple(Channel(c.name, c.times, c.values, sigma[c.name]) if c.name in sigma else c
                                  for c in self.channels))

    def subset(self, names: Sequence[str]) -> "Measurements":
        """Only the named channels (in that order)."""
        return Measurements(tuple(self[n] for n in names))

    def window(self, t_start: float, t_end: float) -> "Measurements":
        """Samples with ``t_start <= t <= t_end`` (for hold-out checks)."""
        out = []
        for c in self.channels:
            keep = (c.times >= t_start) & (c.times <= t_end)
            if not keep.any():
                raise DataError(f"channel {c.name!r} has no samples in [{t_start:g}, {t_end:g}]")
            out.append(c.select(keep))
        return Measurements(tuple(out))

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write a CSV with columns ``t`` and one per channel; a channel not measured at a row's
        time has an empty cell there (channels sampled at other times, drop-outs)."""
        t = np.unique(np.concatenate([c.times for c in self.channels]))
        cols = [[repr(float(v)) for v in t]]
        for c in self.channels:
            cell = [""] * t.size
            for i, v in zip(np.searchsorted(t, c.times), c.values):
                cell[i] = repr(float(v))
            cols.append(cell)
        return write_csv(path, ["t", *self.names], zip(*cols))


def sigma_request(sigma, channels: Sequence[str], where: str = "sigma") -> tuple[dict[str, float], tuple[str, ...]]:
    """Split a noise-level request into given values and channels to estimate.

    Parameters
    ----------
    sigma : None, "estimate", or mapping
        None: nothing requested (the data's or the model's sigma). ``"estimate"``: every
        channel's sigma is estimated. A mapping ``{channel: value or "estimate"}``.
    channels : sequence of str
        The channels that may be named.
    where : str
        How the request is called in messages (``"sigma"``, ``"--sigma"``).

    Returns
    -------
    given : dict
        ``{channel: sigma}`` given as numbers.
    estimated : tuple of str
        Channels whose sigma is estimated, in the order of ``channels``.

    Raises
    ------
    DataError
        An unknown channel, or a value that is neither a positive number nor "estimate".
    """
    channels = tuple(channels)
    if sigma is None:
        return {}, ()
    if isinstance(sigma, str):
        if sigma.strip().lower() != ESTIMATE:
            raise DataError(f"{where} = {sigma!r}: give 'estimate' or a mapping {{channel: value or 'estimate'}}")
        return {}, channels
    if not isinstance(sigma, Mapping):
        raise DataError(f"{where} must be 'estimate' or a mapping {{channel: value or 'estimate'}}, "
                        f"got {type(sigma).__name__} {sigma!r}")
    given, estimated = {}, []
    for name, value in sigma.items():
        if name not in channels:
            raise DataError(f"{where} {name}: there is no channel {name!r}; the channels are {', '.join(channels)}")
        if isinstance(value, str) and value.strip().lower() == ESTIMATE:
            estimated.append(name)
            continue
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise DataError(f"{where} {name}={value!r}: give a positive number or 'estimate'") from None
        if not (v > 0 and math.isfinite(v)):
            raise DataError(f"{where} {name}={value!r}: sigma must be positive and finite (or 'estimate')")
        given[name] = v
    return given, tuple(c for c in channels if c in estimated)


DIFFERENCE_ORDER = 4
"""Order ``k`` of the differences :func:`difference_noise` takes: a smooth signal contributes ``y^(k) dt^k`` to
them (a launch vehicle's downrange sampled at 1 Hz has a fourth derivative of order 0.01-0.1 m/s^4:
centimetres), white noise ``sigma sqrt(C(2k, k))`` (``sqrt(70) sigma`` for k = 4)."""


def steady_runs(times: Sequence[float], gap: float = 1.5) -> list:
    """Index arrays of the runs of steady sampling of ``times``: a run ends where the interval grows beyond
    ``gap`` times the median interval (a drop-out, a change of rate)."""
    t = np.asarray(times, float)
    dt = np.diff(t)
    if dt.size == 0:
        return [np.arange(t.size)]
    return np.split(np.arange(t.size), np.flatnonzero(dt > gap * float(np.median(dt))) + 1)


def difference_noise(channel: "Channel", order: int = DIFFERENCE_ORDER, *, gap: float = 1.5) -> tuple[float, int]:
    """A channel's noise level from the data alone: the scatter of its ``order``-th differences.

    For white noise of standard deviation ``sigma`` on a smooth signal sampled at a steady rate,
    ``Delta^k y_i = sum_j (-1)^j C(k, j) y_{i+j}`` has variance ``C(2k, k) sigma^2`` plus the signal's
    ``(y^(k) dt^k)^2``, which dense sampling makes negligible: ``sigma^2 = mean((Delta^k y)^2) / C(2k, k)``
    (the difference-based variance estimators of nonparametric regression: Rice 1984; Gasser, Sroka and
    Jennen-Steinmetz 1986). Differences are taken only inside runs of steady sampling: a run ends where
    the interval grows beyond ``gap`` times the channel's median interval (a drop-out, a change of rate).
    Quantization is part of the scatter (a step ``q`` adds about ``q^2 / 12``). Errors correlated from
    sample to sample cancel in the differences, so for them this is the scatter from one sample to the
    next, below the errors' full size.

    Returns
    -------
    sigma : float
    n : int
        The number of differences it rests on.

    Raises
    ------
    DataError
        Fewer than 10 differences in runs of steady sampling.
    """
    t, y = np.asarray(channel.times, float), np.asarray(channel.values, float)
    k = int(order)
    if t.size < k + 11:
        raise DataError(f"channel {channel.name!r}: {t.size} samples cannot give its noise from the data alone "
                        f"(at least {k + 11} in steady runs are needed); give its sigma")
    coef = np.array([(-1) ** j * math.comb(k, j) for j in range(k + 1)], float)
    total, n = 0.0, 0
    for run in steady_runs(t, gap):
        if run.size > k:
            d = np.convolve(y[run], coef, mode="valid")
            total += float(np.dot(d, d))
            n += d.size
    if n < 10:
        raise DataError(f"channel {channel.name!r}: only {n} differences in runs of steady sampling; its noise cannot "
                        "be estimated from the data alone -- give its sigma")
    return math.sqrt(total / n / math.comb(2 * k, k)), n


def quantization_step(values: Sequence[float], *, rtol: float = 1e-6) -> float | None:
    """The step of a quantized channel: the smallest gap between its distinct values, when every
    value lies on that lattice (within ``rtol`` of the step); None otherwise."""
    u = np.unique(np.asarray(values, float))
    if u.size < 3:
        return None
    d = np.diff(u)
    q = float(np.min(d))
    if not q > 0:
        return None
    k = (u - u[0]) / q
    if np.max(np.abs(k - np.round(k))) > max(rtol * max(1.0, float(np.max(k))), 1e-3):
        return None
    return q


def resolve_quantized(sigma, data: "Measurements"):
    """Replace ``"quantized"`` and ``"quantized:STEP"`` entries of a ``sigma=`` mapping by the
    standard deviation of rounding to the step, ``STEP / sqrt(12)`` (the step found in the data
    when it is not given).

    Raises
    ------
    DataError
        A channel whose values are not on a common step, or a step that is not a positive number.
    """
    if not isinstance(sigma, Mapping):
        return sigma
    out = dict(sigma)
    for name, value in sigma.items():
        if not (isinstance(value, str) and value.strip().lower().startswith(QUANTIZED)):
            continue
        text = value.strip().lower()
        if text == QUANTIZED:
            if name not in data.names:
                raise DataError(f"sigma {name}={value}: there is no channel {name!r}; the channels are "
                                f"{', '.join(data.names)}")
            q = quantization_step(data[name].values)
            if q is None:
                raise DataError(f"sigma {name}=quantized: the values of channel {name!r} are not on a common step "
                                f"(not quantized, or too few distinct values); give the step: {name}=quantized:STEP")
        else:
            head, _, step = text.partition(":")
            try:
                q = float(step)
                if head != QUANTIZED or not (q > 0 and math.isfinite(q)):
                    raise ValueError
            except ValueError:
                raise DataError(f"sigma {name}={value!r}: write quantized or quantized:STEP with a positive step "
                                "(for example quantized:0.2778)") from None
        out[name] = q / math.sqrt(12.0)
    return out


def read_csv(path: str | os.PathLike, channels: Sequence[str] = ("x", "h", "v"), *,
             time_column: str = "t", column_map: Mapping[str, str] | None = None,
             sigma: Mapping[str, float] | None = None, missing: str = "error",
             sigma_columns: Mapping[str, str] | None = None) -> Measurements:
    """Read measurements from a CSV file with a header row.

    Parameters
    ----------
    path : path-like
    channels : sequence of str
        The model outputs to read.
    time_column : str
        Name of the time column (seconds).
    column_map : mapping, optional
        ``{output name: CSV column}`` where the file's names differ.
    sigma : mapping, optional
        Noise standard deviation per channel (default: the model's).
    missing : {"error", "skip", "auto"}
        A channel without a column: an error; left out (an output the data do not measure,
        predicted but not fitted); or left out only when the file has no column that goes
        unread (otherwise the missing one is probably misnamed: an error).
    sigma_columns : mapping, optional
        ``{output name: CSV column}``: the column holding each sample's noise standard deviation
        of that output (per-sample sigma; a cell may be empty only where the output's is). Not
        together with ``sigma`` for the same output.

    Returns
    -------
    Measurements
        An empty cell means "not measured at that time": each channel has its own sample
        times (multi-rate telemetry, drop-outs).

    Raises
    ------
    DataError
        Missing file or columns, non-numeric cells, NaN, unsorted or duplicate times; a sigma
        column that is missing, or has an empty, negative, zero or non-finite cell where the
        output is measured.
    """
    path = Path(path)
    if path.is_dir():
        raise DataError(f"data file {str(path)!r} is a folder; give a CSV file")
    if not path.is_file():
        raise DataError(f"data file {str(path)!r} does not exist")
    column_map = dict(column_map or {})
    text = _decode(path)
    first = next((line for line in text.splitlines() if line.strip()), "")
    delimiter = _delimiter(first)
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    header = None
    for r in reader:
        if any(cell.strip() for cell in r):
            header = [h.strip() for h in r]
            break
    if header is None:
        raise DataError(f"{path}: the file is empty; expected a header row with {time_column}, "
                        f"{', '.join(channels)}")
    rows, lines = [], []
    for r in reader:
        if any(cell.strip() for cell in r):
            rows.append(r)
            lines.append(reader.line_num)
    if missing not in ("error", "skip", "auto"):
        raise DataError(f"missing must be 'error', 'skip' or 'auto', got {missing!r}")
    wanted = {time_column: time_column, **{c: column_map.get(c, c) for c in channels}}
    absent = [col for col in wanted.values() if col not in header]
    unread = [h for h in header if h and h not in wanted.values() and h not in dict(sigma_columns or {}).values()]
    skip = time_column not in absent and len(absent) < len(channels) and (
        missing == "skip" or (missing == "auto" and not unread))
    if absent and skip:
        channels = [c for c in channels if wanted[c] in header]
        wanted = {time_column: time_column, **{c: column_map.get(c, c) for c in channels}}
    elif absent:
        hint = ""
        if delimiter == "," and len(header) == 1:
            hint = " (the header has no commas: is the file separated by commas?)"
        unmeasured = ""
        if missing == "auto" and time_column not in absent and len(absent) < len(channels):
            names = [c for c in channels if wanted[c] in absent]
            unmeasured = (f"; if {', '.join(names)} {'is' if len(names) == 1 else 'are'} not measured, say so "
                          f"(CLI: --unmeasured {names[0]})")
        raise DataError(f"{path}: missing column(s) {', '.join(absent)}; the file has {', '.join(header)}{hint}. "
                        f"Rename the columns or map them (CLI: --column NAME=COLUMN, API: column_map=){unmeasured}")
    sigma_columns = dict(sigma_columns or {})
    both = [k for k in sigma_columns if k in (sigma or {})]
    if both:
        raise DataError(f"sigma of {', '.join(both)} is given both as a number and as a column "
                        f"({', '.join(sigma_columns[k] for k in both)}); give one (drop --sigma or --sigma-column)")
    for name, col in sigma_columns.items():
        if name not in channels:
            raise DataError(f"sigma column {col!r} is given for {name!r}, which is not a channel read from {path}; "
                            f"the channels are {', '.join(channels)}")
        if col not in header:
            raise DataError(f"{path}: no column {col!r} for the per-sample sigma of {name} (sigma column {name}={col}); "
                            f"the file has {', '.join(header)}. Name an existing column (CLI: --sigma-column "
                            f"{name}=COLUMN, API: sigma_columns=)")
        if col in wanted.values():
            raise DataError(f"{path}: column {col!r} is read as data; the per-sample sigma of {name} must be a column "
                            "of its own")
    wanted_sigma = {f"sigma:{k}": v for k, v in sigma_columns.items()}
    twice = sorted({col for col in [*wanted.values(), *wanted_sigma.values()] if header.count(col) > 1})
    if twice:
        raise DataError(f"{path}: column(s) {', '.join(twice)} appear more than once in the header; rename or "
                        "remove the extra column so that it is clear which one to read")
    wanted = {**wanted, **wanted_sigma}
    idx = {key: header.index(col) for key, col in wanted.items()}
    data = {key: np.empty(len(rows)) for key in idx}
    empty = {key: np.zeros(len(rows), bool) for key in idx}
    for i, (r, line) in enumerate(zip(rows, lines)):
        if len(r) < len(header) and max(idx.values()) >= len(r):
            raise DataError(f"{path}, line {line}: {len(r)} cells, but the header has {len(header)} columns; "
                            "complete the row or remove it")
        for key, j in idx.items():
            cell = r[j].strip() if j < len(r) else ""
            if not cell:
                if key == time_column:
                    raise DataError(f"{path}, line {line}: the time cell ({time_column!r}) is empty; every row needs "
                                    "its time (an empty channel cell means 'not measured then')")
                empty[key][i] = True
                data[key][i] = math.nan
                continue
            try:
                data[key][i] = float(cell)
            except ValueError:
                hint = ("; decimal commas are not read: use a point (1.5, not 1,5)"
                        if delimiter != "," and "," in cell else "")
                raise DataError(f"{path}, line {line}, column {wanted[key]!r}: {cell!r} is not a number{hint}") from None
    if not rows:
        raise DataError(f"{path}: no data rows")
    never = [wanted[c] for c in channels if empty[c].all()]
    if never:
        raise DataError(f"{path}: column(s) {', '.join(never)} have no values (every cell is empty); fill them or "
                        "leave the output out of the model's measured outputs")
    sigma = dict(sigma or {})
    unknown = [k for k in sigma if k not in channels]
    if unknown:
        raise DataError(f"sigma is given for {', '.join(map(repr, unknown))}, which is not a channel; "
                        f"the channels are {', '.join(channels)}")
    t = data[time_column]
    for c, col in sigma_columns.items():
        key = f"sigma:{c}"
        s = data[key]
        bad = np.flatnonzero(~empty[c] & (empty[key] | ~np.isfinite(s) | ~(s > 0)))
        if bad.size:
            i = int(bad[0])
            what = "is empty" if empty[key][i] else f"is {s[i]:g}, not a positive finite number"
            raise DataError(f"{path}, line {lines[i]}, column {col!r} (per-sample sigma of {c}): the cell {what} where "
                            f"{c} is measured ({bad.size} such row(s)); every measured sample needs a positive sigma")
        sigma[c] = s[~empty[c]]
    try:
        # an empty cell: that channel was not measured at that time (multi-rate telemetry, drop-outs)
        return Measurements(tuple(Channel(c, t[~empty[c]], data[c][~empty[c]], sigma.get(c)) for c in channels))
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


def read_channels(files: Mapping[str, str | os.PathLike], *, time_column: str = "t",
                  column_map: Mapping[str, str] | None = None,
                  sigma: Mapping[str, float] | None = None,
                  sigma_columns: Mapping[str, str] | None = None) -> Measurements:
    """Read measurements from one CSV file per channel, each with its own sample times.

    Parameters
    ----------
    files : mapping
        ``{output name: CSV path}``; each file has the time column and the channel's column
        (named like the output, or mapped by ``column_map``).
    time_column, column_map, sigma, sigma_columns
        As for :func:`read_csv`.

    Returns
    -------
    Measurements
        The same as one CSV with the channels side by side and empty cells where a channel
        was not measured.
    """
    if not isinstance(files, Mapping) or not files:
        raise DataError("files must be a non-empty mapping {output name: CSV path}")
    column_map = dict(column_map or {})
    sigma = dict(sigma or {})
    sigma_columns = dict(sigma_columns or {})
    unknown = [k for k in sigma_columns if k not in files]
    if unknown:
        raise DataError(f"sigma column given for {', '.join(map(repr, unknown))}, which has no file; the channels are "
                        f"{', '.join(files)}")
    channels = []
    for name, path in files.items():
        one = read_csv(path, [name], time_column=time_column, column_map={name: column_map.get(name, name)},
                       sigma={name: sigma[name]} if name in sigma else None,
                       sigma_columns={name: sigma_columns[name]} if name in sigma_columns else None)
        channels.append(one[name])
    return Measurements(tuple(channels))


def _decode(path: Path) -> str:
    """The text of a CSV file: UTF-8 with or without a byte-order mark; anything else is refused."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"cannot read data file {str(path)!r}: {exc.strerror or exc}") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise DataError(f"{path}: the file is UTF-16 text; save it as UTF-8 (with or without BOM)")
    if b"\x00" in raw[:4096]:
        raise DataError(f"{path}: the file is binary (it holds NUL bytes), not a CSV text file")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise DataError(f"{path}: the file is not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}; "
                        "perhaps Latin-1 or Windows-1252); save it as UTF-8") from None


def _delimiter(header_line: str) -> str:
    """``,``; or ``;`` or a tab when the header has no comma but one of those."""
    if "," in header_line:
        return ","
    for d in (";", "\t"):
        if d in header_line:
            return d
    return ","
