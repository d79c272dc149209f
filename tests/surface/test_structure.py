"""The surfacer's layout: one module per pass with both variants in it, the choice of variant in
one table (mpmfx.surface.variants), no import cycles, imports at the top of each module."""

import ast
import dataclasses
from pathlib import Path

import pytest

SURFACE = Path(__file__).resolve().parents[2] / "mpmfx" / "surface"


def module_imports() -> dict[str, set[str]]:
    """mpmfx.surface module name -> the mpmfx.surface modules it imports at its top level."""
    names = {p.stem for p in SURFACE.glob("*.py")}
    graph = {}
    for path in SURFACE.glob("*.py"):
        deps = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mpmfx.surface"):
                tail = node.module.split(".")[2:]
                if tail:
                    deps.add(tail[0])
                else:
                    deps.update(a.name for a in node.names if a.name in names)
            elif isinstance(node, ast.Import):
                deps.update(a.name.split(".")[2] for a in node.names if a.name.startswith("mpmfx.surface."))
        graph[path.stem] = deps - {path.stem}
    return graph


def test_no_import_cycles_inside_surface():
    graph = module_imports()
    state: dict[str, int] = {}

    def visit(name, stack):
        state[name] = 1
        for dep in sorted(graph.get(name, ())):
            if state.get(dep) == 1:
                raise AssertionError("import cycle: " + " -> ".join([*stack, name, dep]))
            if dep not in state:
                visit(dep, [*stack, name])
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [])


def test_imports_sit_at_the_top_or_name_their_boundary():
    for path in SURFACE.glob("*.py"):
        lines = path.read_text().splitlines()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                for inner in ast.walk(node):
                    if isinstance(inner, (ast.Import, ast.ImportFrom)):
                        line = lines[inner.lineno - 1]
                        assert "# backend:" in line or "# optional:" in line, (
                            f"{path.name}:{inner.lineno}: {line.strip()}"
                        )


def test_modules_stay_small():
    for path in SURFACE.glob("*.py"):
        assert len(path.read_text().splitlines()) <= 600, path.name


def test_each_variant_has_every_pass_from_its_pass_module():
    pytest.importorskip("warp")
    from mpmfx.surface import variants

    for field in dataclasses.fields(variants.Variant):
        if field.name == "name":
            continue
        voxel, block = getattr(variants.BY_VOXEL, field.name), getattr(variants.BY_BLOCK, field.name)
        assert voxel.__name__.endswith("_by_voxel") and block.__name__.endswith("_by_block"), field.name
        assert voxel.__module__ == block.__module__, field.name  # both variants of a pass side by side
