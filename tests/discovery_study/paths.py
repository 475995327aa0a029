"""Where the study's files are, and the third vehicle's model file as a module."""

from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent
STAGE30 = TESTS / "vehicles" / "stage30.py"


def load_stage30():
    """The Stage-30 model file, imported as a module (its constants and program)."""
    name = "rocketid_study_stage30"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, STAGE30)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def cache_dir() -> Path:
    """Generated data live here (``ROCKETID_STUDY_DIR``, default ``<tmp>/rocketid-study``), never
    in the repository."""
    d = Path(os.environ.get("ROCKETID_STUDY_DIR", Path(tempfile.gettempdir()) / "rocketid-study"))
    d.mkdir(parents=True, exist_ok=True)
    return d
