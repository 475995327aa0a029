"""Imports flow only downstream in the pipeline (STYLE.md, docs/design.md).

Every module of the package is parsed with ``ast`` (no import is executed) and
each of its imports of ``rocketid`` code, at module level or inside a function,
must name its own stage or an earlier one. Stages that do not exist yet are
listed so that they are checked from the moment they appear; a module that is
in no stage fails the test, so that a new module takes its place on purpose.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = "rocketid"
SRC = Path(__file__).resolve().parents[1] / "src" / PACKAGE

#: The pipeline, upstream first. A module may import its own stage and earlier ones.
#: ``simulate`` comes right after ``model``: the truth data must share nothing with the
#: collocation it checks (it uses only errors, data, model and the printing of expressions).
LAYERS: list[tuple[str, ...]] = [
    ("errors",),
    ("output",),         # atomic writes and output locations: every file rocketid writes
    ("summary",),        # the Summary value every stage's results render (text, HTML)
    ("data",),
    ("model",),
    ("tables", "printing"),  # tabulated functions for models; NumPy printing of model expressions
    ("simulate",),
    ("physics",),
    ("symbolic",),
    ("codegen",),
    ("collocation",),
    ("cases",),
    ("examples",),       # shipped real data and the models that go with them
    ("start",),          # starting points from the data, flight windows, sanity checks
    ("nlp",),
    ("solve",),
    ("sensitivity",),
    ("estimability",),
    ("joint",),          # several flights fitted jointly (shared and per-flight parameters)
    ("sampling",),       # statistic-criterion sampling (7.10)
    ("study",),          # the chapter's RA-66 study (Tables 7.1-7.3) on top of sampling
    ("diagnostics",),    # compare, locate, candidate effects, score test, report
    ("reports", "plots"),  # not written yet
    ("cli", "commands"),  # the command line may import anything; cli_<name> modules too
]
#: Not a stage: the package's front door imports every stage.
FACADE = {"__init__", "__main__"}

RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}
TOP = len(LAYERS) - 1


def stage_of(top_name: str) -> int | None:
    """The rank of a top-level module or subpackage of rocketid."""
    if top_name in RANK:
        return RANK[top_name]
    if top_name.startswith("cli_"):
        return TOP
    return None


def package_modules() -> list[tuple[str, Path]]:
    """``(dotted name relative to rocketid, path)`` of every module of the package."""
    out = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__" and len(parts) > 1:
            parts = parts[:-1] + ["__init__"]
        out.append((".".join(parts), path))
    return out


def rocketid_imports(module: str, path: Path) -> list[tuple[int, str]]:
    """``(line, imported dotted name relative to rocketid)`` for every import of package code;
    ``""`` means the package root itself."""
    tree = ast.parse(path.read_text(), filename=str(path))
    parts = module.split(".")
    package_parts = parts[:-1]  # the package the module lives in, relative to rocketid
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == PACKAGE or alias.name.startswith(PACKAGE + "."):
                    out.append((node.lineno, alias.name[len(PACKAGE) + 1:]))
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if node.module != PACKAGE and not (node.module or "").startswith(PACKAGE + "."):
                    continue
                base = (node.module or "")[len(PACKAGE) + 1:].split(".") if node.module != PACKAGE else []
            else:
                if node.level - 1 > len(package_parts):
                    raise AssertionError(f"{path}:{node.lineno}: relative import beyond the package")
                base = package_parts[:len(package_parts) - (node.level - 1)]
                if node.module:
                    base = base + node.module.split(".")
            base = [b for b in base if b]
            if base and node.level > 0 and not node.module:  # from . import radau
                out.extend((node.lineno, ".".join([*base, alias.name])) for alias in node.names)
            elif base:
                out.append((node.lineno, ".".join(base)))
            else:  # from rocketid import x / from . import x (at the top): x is a submodule or a name
                for alias in node.names:
                    name = alias.name
                    out.append((node.lineno, name if stage_of(name) is not None or (SRC / f"{name}.py").exists()
                                or (SRC / name).is_dir() else ""))
    return out


MODULES = package_modules()


def test_the_pipeline_modules_exist():
    names = {m.split(".")[0] for m, _ in MODULES}
    assert {"errors", "data", "model", "symbolic", "codegen", "collocation", "nlp", "solve", "simulate",
            "cli"} <= names


def test_every_module_has_a_stage():
    missing = sorted({m.split(".")[0] for m, _ in MODULES if m not in FACADE and stage_of(m.split(".")[0]) is None})
    assert not missing, (f"module(s) {', '.join(missing)} are in no pipeline stage: add each to LAYERS in "
                         "tests/test_architecture.py, after every stage it imports")


@pytest.mark.parametrize("module, path", [pytest.param(m, p, id=m) for m, p in MODULES if m not in FACADE])
def test_imports_flow_downstream(module, path):
    own_top = module.split(".")[0]
    own = stage_of(own_top)
    if own is None:
        pytest.skip(f"{module} has no stage (reported by test_every_module_has_a_stage)")
    bad = []
    for line, target in rocketid_imports(module, path):
        top = target.split(".")[0]
        if top == "":
            if own != TOP:
                bad.append(f"line {line}: imports the package root {PACKAGE!r} (which imports every stage); "
                           "import the module it needs instead")
            continue
        if top == own_top:
            continue
        rank = stage_of(top)
        if rank is None:
            bad.append(f"line {line}: imports {PACKAGE}.{target}, which is in no stage")
        elif rank > own:
            bad.append(f"line {line}: imports {PACKAGE}.{target} (stage {LAYERS[rank][0]!r}), downstream of "
                       f"{module} (stage {LAYERS[own][0]!r})")
    assert not bad, f"{module}:\n  " + "\n  ".join(bad)


def test_the_checker_catches_an_upstream_import(tmp_path):
    src = tmp_path / "probe.py"
    src.write_text("from ..solve import estimate\nimport rocketid.cli\nfrom . import radau\nfrom .. import model\n"
                   "def f():\n    from rocketid import nlp\n")
    found = rocketid_imports("collocation.probe", src)
    assert sorted(t for _, t in found) == ["cli", "collocation.radau", "model", "nlp", "solve"]
