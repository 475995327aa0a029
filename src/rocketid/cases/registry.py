"""The built-in models by name, and the one resolver of a ``model`` argument.

The command line (``--model``) and the API (``diagnose(model=...)``) accept the same
things: a built-in name (:data:`BUILTIN_MODELS`), a :class:`~rocketid.model.ModelSpec` or
:class:`~rocketid.model.Model`, or the path of a Python file whose ``build_model()``
returns the model (:func:`~rocketid.cases.files.load_model_file`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from ..errors import ModelError, RocketidError
from ..model import Model, ModelSpec
from .files import call_hook, load_model_file
from .ra66 import ra66, ra66_times, ra66_truth
from .ra66m import ra66m, ra66m_truth

__all__ = ["BuiltinModel", "BUILTIN_MODELS", "ModelSource", "load_model", "resolve_model"]


@dataclass(frozen=True)
class BuiltinModel:
    """A model shipped with rocketid.

    Attributes
    ----------
    name : str
        What ``--model`` accepts.
    build : callable
        ``build() -> ModelSpec``.
    truth : callable
        ``truth(spec) -> ndarray``: the true parameters of the reference flight.
    times : callable
        ``times() -> ndarray``: the sample times of the reference data.
    description : str
    """

    name: str
    build: Callable[[], ModelSpec]
    truth: Callable[[ModelSpec], np.ndarray]
    times: Callable[[], np.ndarray]
    description: str


#: Built-in models by name: the chapter's parameterization and the Mach-indexed one.
BUILTIN_MODELS: Mapping[str, BuiltinModel] = {
    "ra66": BuiltinModel("ra66", ra66, ra66_truth, ra66_times, "the chapter's RA-66: time-knot CD(t), CL"),
    "ra66m": BuiltinModel("ra66m", ra66m, ra66m_truth, ra66_times,
                          "RA-66M: RA-66's vehicle, CD(Mach), CL = CL_alpha alpha, an attack-angle excitation"),
}


@dataclass(frozen=True)
class ModelSource:
    """A model with the flight that goes with it.

    Attributes
    ----------
    spec : ModelSpec
    label : str
        What the user passed (``ra66``, ``ra66m`` or the file path).
    truth : ndarray, shape (n_p,)
        Parameters that ``rocketid simulate`` uses (a built-in model: its truth; a model
        file: its ``truth(spec)`` if defined, else the guesses p0).
    times : ndarray, shape (n,)
        Sample times of ``rocketid simulate`` (RA-66 and RA-66M: 0.01 k s, k = 1..6600; a
        model file: its ``sample_times()`` if defined, else 1001 points over the horizon).
    """

    spec: ModelSpec
    label: str
    truth: np.ndarray
    times: np.ndarray


def _unknown(key: str) -> ModelError:
    return ModelError(f"unknown model {key!r}: use one of {', '.join(sorted(BUILTIN_MODELS))} or the path of a "
                      "Python file (.py) that defines build_model()")


def load_model(name_or_path: str | Path) -> ModelSource:
    """Resolve a model name or file with its truth and sample times.

    A model file defines ``build_model()`` returning a :class:`ModelSpec` (a
    :class:`Model` is frozen for you). It may also define ``truth(spec)`` (a
    parameter vector or ``{name: value}`` mapping for ``simulate``) and
    ``sample_times()`` (the times ``simulate`` samples at).

    Raises
    ------
    ModelError
        Unknown name, missing file, no ``build_model``, or a file that fails.
    """
    key = str(name_or_path)
    if key in BUILTIN_MODELS:
        b = BUILTIN_MODELS[key]
        spec = b.build()
        return ModelSource(spec, key, b.truth(spec), b.times())
    if Path(key).is_dir():
        raise ModelError(f"--model {key!r} is a folder, not a model: give a built-in model "
                         f"({', '.join(sorted(BUILTIN_MODELS))}) or a model file, a Python file (.py) that "
                         "defines build_model() returning the model (see 'Model files' in docs/cli.md)")
    if Path(key).suffix != ".py":
        raise _unknown(key)
    spec, module = load_model_file(key)
    truth = spec.guess
    if callable(getattr(module, "truth", None)):
        value = call_hook(key, module, "truth", spec)
        try:
            truth = spec.parameter_vector(value)
        except RocketidError as exc:
            raise ModelError(f"model file {key!r}: truth(spec) returned an unusable value: {exc}") from None
    if callable(getattr(module, "sample_times", None)):
        value = call_hook(key, module, "sample_times")
        try:
            times = np.asarray(value, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ModelError(f"model file {key!r}: sample_times() must return numbers, got {value!r:.60}") from None
        if times.size == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise ModelError(f"model file {key!r}: sample_times() must return finite, strictly increasing times")
    else:
        times = np.linspace(spec.t0, spec.tf, 1001)
    return ModelSource(spec, key, truth, times)


def resolve_model(model: str | Path | ModelSpec | Model) -> tuple[ModelSpec, str]:
    """A model argument as ``(spec, label)``.

    Parameters
    ----------
    model : str, Path, ModelSpec or Model
        A built-in name (:data:`BUILTIN_MODELS`), a model (a :class:`Model` is
        frozen here), or a Python file whose ``build_model()`` returns one.

    Raises
    ------
    ModelError
        Unknown name, missing file, no ``build_model``, or a file that fails.
    """
    if isinstance(model, ModelSpec):
        return model, model.name
    if isinstance(model, Model):
        spec = model.freeze()
        return spec, spec.name
    if not isinstance(model, (str, Path)):
        raise ModelError(f"model must be one of {', '.join(sorted(BUILTIN_MODELS))}, a ModelSpec or the path of a "
                         f"model file, got {type(model).__name__}")
    key = str(model)
    if key in BUILTIN_MODELS:
        return BUILTIN_MODELS[key].build(), key
    if Path(key).is_dir():
        raise ModelError(f"--model {key!r} is a folder, not a model: give a built-in model "
                         f"({', '.join(sorted(BUILTIN_MODELS))}) or a model file, a Python file (.py) that "
                         "defines build_model() returning the model (see 'Model files' in docs/cli.md)")
    if Path(key).suffix != ".py":
        raise _unknown(key)
    spec, _ = load_model_file(key)
    return spec, key
