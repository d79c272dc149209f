"""The import rules of docs/architecture.md, checked on the source: what each layer may import."""
from __future__ import annotations

import ast
from pathlib import Path

from mpmfx.stages import STAGES

PACKAGE = Path(__file__).resolve().parents[2] / "mpmfx"


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the file's package
                parts = path.relative_to(PACKAGE.parent).with_suffix("").parts[: -node.level]
                base = ".".join([*parts, base] if base else parts)
            names |= {base} | {f"{base}.{a.name}" for a in node.names}
    return names


def test_no_stage_imports_a_sibling_stage():
    for name in STAGES:
        siblings = {f"mpmfx.stages.{s}" for s in STAGES if s != name}
        bad = _imports(PACKAGE / "stages" / f"{name}.py") & siblings
        assert not bad, f"stages/{name}.py imports {sorted(bad)}: exchange data through mpmfx.io records"


def test_the_solver_imports_only_numpy_and_warp():
    for path in (PACKAGE / "mpm").glob("*.py"):
        outside = {n.split(".")[0] for n in _imports(path) if not n.startswith("mpmfx.mpm")}
        assert outside <= {"numpy", "warp", "__future__", "dataclasses", "enum", "math", "typing", "importlib",
                           "collections", "functools", "time", "logging", "os", "sys"}, (path.name, outside)


def test_stages_declare_code_that_exists():
    from mpmfx.cache import code_hash
    from mpmfx.stages.runner import MODULES
    for name, mod in MODULES.items():
        assert f"mpmfx.stages.{name}" in mod.CODE
        code_hash(mod.CODE)  # raises on a module that does not exist
