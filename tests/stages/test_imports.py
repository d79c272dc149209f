"""The import rules of docs/architecture.md ("Layers", "Import rules"), checked on the source:
what each layer may import.

Every import statement of every module under mpmfx/ counts, at the top of a module or inside a
function: the graph here is the one that runs, not only the one the top of a file shows.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from mpmfx.cache import code_hash
from mpmfx.stages import STAGES
from mpmfx.stages.runner import MODULES

PACKAGE = Path(__file__).resolve().parents[2] / "mpmfx"

# What a function-level import may load, and the marker it carries on its line:
# `# optional: NAME` (a package that may be missing) or `# backend: NAME` (a heavy engine).
OPTIONAL = {"bpy", "bmesh", "mathutils", "pyopenvdb", "pyvista", "matplotlib", "pysplashsurf", "newton", "taichi"}
BACKEND = {"pxr", "dask", "distributed"}
# Heavy for the command line's start-up only: deferred in the modules `mpmfx --help` imports.
START_UP = {"warp", "pydantic", "trimesh", "scipy"}
MARKER = re.compile(r"#\s*(optional|backend): ([A-Za-z_][A-Za-z0-9_]*)")

# (importer prefix, prefixes it must not import); a prefix names a module and everything below it.
FORBIDDEN = [
    ("mpmfx.io", ("mpmfx.surface", "mpmfx.stages", "mpmfx.geometry", "mpmfx.render", "mpmfx.mpm", "mpmfx.config")),
    ("mpmfx.geometry", ("mpmfx.render", "mpmfx.config", "mpmfx.mpm", "mpmfx.stages", "mpmfx.io", "mpmfx.surface")),
    ("mpmfx.surface", ("mpmfx.stages", "mpmfx.io", "mpmfx.config", "mpmfx.cli", "mpmfx.wedge")),
    ("mpmfx.mpm", ("mpmfx.config", "mpmfx.stages", "mpmfx.io", "mpmfx.geometry", "mpmfx.render", "mpmfx.surface")),
    ("mpmfx.cache", ("mpmfx.mpm",)),
    ("mpmfx.cli", ("mpmfx.mpm",)),
    ("mpmfx.threads", ("mpmfx",)),
    ("mpmfx.blender", ("mpmfx",)),
]
# Modules run only inside Blender's own process: they import bpy, and no other module imports them.
BLENDER_SIDE = {"mpmfx.geometry.blender_export", "mpmfx.render.cycles_job", "mpmfx.render.blender_scene"}


@dataclass(frozen=True)
class Import:
    module: str  # the importing module
    names: tuple  # dotted names the statement imports (a from-import: the module and module.name)
    line: int
    in_function: bool
    text: str  # the statement's source lines


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


@cache
def imports() -> tuple[Import, ...]:
    out = []
    for name, path in modules().items():
        source = path.read_text()
        lines = source.splitlines()
        is_package = path.name == "__init__.py"

        def visit(node, in_function: bool) -> None:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.Import):
                    names = tuple(a.name for a in child.names)
                elif isinstance(child, ast.ImportFrom):
                    base = child.module or ""
                    if child.level:  # relative: resolve against the importing package
                        parts = name.split(".")[: len(name.split(".")) - child.level + is_package]
                        base = ".".join([*parts, base] if base else parts)
                    # `from pkg import submodule` imports the submodule (pkg's __init__ runs as
                    # every parent does); `from module import name` imports the module
                    names = tuple(
                        dict.fromkeys(
                            f"{base}.{a.name}" if f"{base}.{a.name}" in modules() else base for a in child.names
                        )
                    )
                else:
                    visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))
                    continue
                text = "\n".join(lines[child.lineno - 1 : child.end_lineno])
                out.append(Import(name, names, child.lineno, in_function, text))

        visit(ast.parse(source), False)
    return tuple(out)


def _target(name: str) -> str | None:
    """The mpmfx module a dotted name lands in (a name imported from a module: that module)."""
    mods = modules()
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def _edges(*, top_only: bool = False) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in modules()}
    for imp in imports():
        if top_only and imp.in_function:
            continue
        for n in imp.names:
            if n.split(".")[0] == "mpmfx" and (t := _target(n)) and t != imp.module:
                graph[imp.module].add(t)
    return graph


def _parents(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


@cache
def _closure(module: str) -> frozenset[str]:
    """Top-level packages (third-party and stdlib) that importing `module` loads, through the
    top-level imports of the mpmfx modules it pulls in (their packages' __init__ included)."""
    top = _edges(top_only=True)
    seen, todo, outside = set(), [module], set()
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo += [p for p in _parents(m) if p in modules()]
        todo += top[m]
        outside |= {
            n.split(".")[0]
            for i in imports()
            if i.module == m and not i.in_function
            for n in i.names
            if n.split(".")[0] != "mpmfx"
        }
    return frozenset(outside)


@cache
def _start_up() -> frozenset[str]:
    """The modules `mpmfx --help` imports: mpmfx.cli and what it imports at its top, transitively."""
    top = _edges(top_only=True)
    seen, todo = set(), ["mpmfx.cli"]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo += [p for p in _parents(m) if p in modules()] + sorted(top[m])
    return frozenset(seen)


def _in(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def test_each_layer_imports_only_what_is_below_it():
    bad = []
    for imp in imports():
        for importer, forbidden in FORBIDDEN:
            if not _in(imp.module, importer):
                continue
            for n in imp.names:
                hit = [f for f in forbidden if _in(n, f) and not _in(n, importer)]
                if hit:
                    bad.append(f"{imp.module}:{imp.line} imports {n} (not allowed: {hit[0]})")
    assert not bad, "\n".join(sorted(set(bad)))


def test_no_stage_imports_a_sibling_stage():
    for name in STAGES:
        siblings = {f"mpmfx.stages.{s}" for s in STAGES if s != name}
        bad = [
            f"{i.module}:{i.line} imports {n}"
            for i in imports()
            if i.module == f"mpmfx.stages.{name}"
            for n in i.names
            if _target(n) in siblings
        ]
        assert not bad, "\n".join(bad) + "\nexchange data through mpmfx.io records"


def test_stages_declare_code_that_exists():
    for name, mod in MODULES.items():
        assert f"mpmfx.stages.{name}" in mod.CODE
        code_hash(mod.CODE)  # raises on a module that does not exist


def test_the_solver_imports_only_numpy_warp_and_the_standard_library():
    allowed = {"numpy", "warp", *sys.stdlib_module_names}
    bad = [
        f"{i.module}:{i.line} imports {n}"
        for i in imports()
        if _in(i.module, "mpmfx.mpm")
        for n in i.names
        if not _in(n, "mpmfx.mpm") and n.split(".")[0] not in allowed
    ]
    assert not bad, "\n".join(bad)


def test_blender_side_modules_are_imported_only_in_blenders_process():
    bad = [
        f"{i.module}:{i.line} imports {n}"
        for i in imports()
        if i.module not in BLENDER_SIDE
        for n in i.names
        if _target(n) in BLENDER_SIDE or n.split(".")[0] in {"bpy", "bmesh", "mathutils"}
    ]
    assert not bad, "\n".join(bad) + "\nrun them as a child process (mpmfx.blender)"


def test_no_import_cycles():
    graph = _edges()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def strongconnect(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph)))
    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    assert not cycles, "modules that import each other: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_imports_sit_at_the_top_except_marked_boundaries():
    start_up = _start_up()
    bad = []
    for imp in imports():
        if not imp.in_function:
            continue
        where = f"{imp.module}:{imp.line}: {imp.text.strip()}"
        mark = MARKER.search(imp.text)
        if not mark:
            bad.append(f"{where}: move it to the top, or mark the boundary (# optional: NAME / # backend: NAME)")
            continue
        kind, name = mark.groups()
        allowed = OPTIONAL if kind == "optional" else BACKEND | START_UP
        if name not in allowed:
            bad.append(f"{where}: {name} is no {kind} package here ({sorted(allowed)})")
        elif name in START_UP and imp.module not in start_up:
            bad.append(f"{where}: {name} is deferred only where `mpmfx --help` imports the module")
        loads = {n.split(".")[0] for n in imp.names if n.split(".")[0] != "mpmfx"}
        for n in imp.names:
            if n.split(".")[0] == "mpmfx" and (t := _target(n)):
                loads |= _closure(t)
        if name not in loads:
            bad.append(f"{where}: the marker names {name}, which this import does not load")
    assert not bad, "\n".join(bad)


def test_help_loads_no_engine():
    code = (
        "import sys\nfrom mpmfx.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print('loaded:', *sorted({m.split('.')[0] for m in sys.modules}.intersection("
        f"{sorted(START_UP | BACKEND | {'bpy', 'pyvista'})!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PACKAGE.parent)
    assert "usage: mpmfx" in out.stdout
    assert out.stdout.splitlines()[-1] == "loaded:", out.stdout.splitlines()[-1]
