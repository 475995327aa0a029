"""User model files: a Python file whose ``build_model()`` returns the model.

One loader serves the command line (``--model PATH.py``) and the API
(``rocketid.diagnostics.diagnose(model=PATH)``).
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from ..errors import ModelError, RocketidError
from ..model import Model, ModelSpec

__all__ = ["load_model_file", "call_hook", "optional_hook"]


def _module_name(path: Path) -> str:
    return "rocketid_user_model_" + hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]


def _import(path: Path) -> ModuleType:
    name = _module_name(path)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ModelError(f"model file {str(path)!r} cannot be imported; it must be a Python file (.py)")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and inspect look modules up here
    try:
        spec.loader.exec_module(module)
    except RocketidError:
        sys.modules.pop(name, None)
        raise
    except SystemExit as exc:
        sys.modules.pop(name, None)
        raise ModelError(f"model file {str(path)!r} called sys.exit({exc.code!r}) while being imported; a model "
                         "file must only define build_model() (move script code under "
                         "`if __name__ == \"__main__\":`)") from None
    except Exception as exc:
        sys.modules.pop(name, None)
        raise ModelError(f"model file {str(path)!r} failed to import: {type(exc).__name__}: {exc}") from exc
    return module


def call_hook(path: str | Path, module: ModuleType, name: str, *args):
    """Call the model file's optional function ``name`` (``truth``, ``sample_times``),
    turning its failure into a :class:`ModelError` that names the file and the function."""
    try:
        return getattr(module, name)(*args)
    except RocketidError as exc:
        raise type(exc)(f"model file {str(path)!r}: {name}(): {exc}") from None
    except (Exception, SystemExit) as exc:
        raise ModelError(f"model file {str(path)!r}: {name}() failed: {type(exc).__name__}: {exc}; fix the "
                         "function or remove it to use the default") from exc


def load_model_file(path: str | Path) -> tuple[ModelSpec, ModuleType]:
    """Import a model file and build its model.

    The file defines ``build_model()`` returning a :class:`ModelSpec` (a
    :class:`Model` is frozen here); it may define more (the command line reads
    ``truth(spec)`` and ``sample_times()`` from the returned module).

    Returns
    -------
    spec : ModelSpec
    module : module
        The imported file.

    Raises
    ------
    ModelError
        Missing file, not a .py file, no ``build_model``, or a file or
        ``build_model()`` that fails (the message names the file).
    """
    key = str(path)
    path = Path(path)
    if path.suffix != ".py":
        raise ModelError(f"model file {key!r} is not a Python file (.py) that defines build_model()")
    if not path.is_file():
        raise ModelError(f"model file {key!r} does not exist")
    module = _import(path)
    build = getattr(module, "build_model", None)
    if not callable(build):
        raise ModelError(f"model file {key!r} does not define build_model(); add a function build_model() that "
                         "returns a ModelSpec (Model(...).freeze())")
    try:
        spec = build()
        if isinstance(spec, Model):
            spec = spec.freeze()
    except RocketidError as exc:
        raise type(exc)(f"model file {key!r}: {exc}") from exc
    except (Exception, SystemExit) as exc:
        raise ModelError(f"model file {key!r}: build_model() failed: {type(exc).__name__}: {exc}") from exc
    if not isinstance(spec, ModelSpec):
        raise ModelError(f"model file {key!r}: build_model() returned {type(spec).__name__}, not a ModelSpec; "
                         "return Model(...).freeze()")
    return spec, module


def optional_hook(path: str | Path, name: str):
    """The value of the model file's optional function ``name()`` (:func:`call_hook`), None when the file
    does not define it. The file is imported once (the module :func:`load_model_file` made is reused)."""
    module = sys.modules.get(_module_name(Path(path))) or _import(Path(path))
    if not callable(getattr(module, name, None)):
        return None
    return call_hook(path, module, name)
