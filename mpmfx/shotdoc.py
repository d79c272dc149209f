"""docs/shots.md, the shot field reference, rendered from the schema's own descriptions.

`mpmfx docs --write` writes it, `mpmfx docs --check` exits 1 when it is stale; the text of every
row is the `description` of a field of `mpmfx.config`, so the reference is edited there.
"""

from __future__ import annotations

import enum
import inspect
import types
import typing
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel
from pydantic.fields import FieldInfo

from mpmfx.config import Shot

DOC = Path(__file__).resolve().parents[1] / "docs" / "shots.md"

INTRO = """\
# Shot file reference

A shot is one TOML file: the meshes to simulate and how, from voxelising to the render. Every
example in `pipeline/shots/` is a runnable shot. Any field can be changed for one run without
editing the file: `mpmfx run SHOT --set solver.cfl=0.3 --set objects.0.material=Water`.

Units are world units: metres, seconds, degrees. Material moduli are the exception: they are
given in the solver's normalised domain (see docs/physics.md, "Materials"), so a preset looks the
same in a 1 m box and in a 10 m box.

A minimal shot: one mesh, dropped as jelly, everything else at its default.

```toml
[shot]
name = "drop"
frame_end = 24

[[objects]]
name = "bear"
mesh = "../../assets/jelly_bear.obj"   # relative to the shot file
material = "Elastic"
translate = [0.0, 0.5, 0.0]
```

The bear (`assets/jelly_bear.obj`, also in `jelly_splash`) is a union of spheres and capsules
(`assets/make_assets.py`), not a sculpted model: its blobby shape is the asset's, and the
surfacer keeps it. A shot looks as detailed as the mesh it is given.

Unknown keys, wrong types and values out of range stop the run before anything is computed, with
a message that names the file, the key and the fix.

This page is generated from the schema (`mpmfx/config.py`) by `mpmfx docs --write`; a test fails
when it is stale. Edit the descriptions there, not here.
"""


def _name(tp: Any) -> str:
    """A field's type as a shot author reads it."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Annotated:
        return _name(args[0])
    if origin in (typing.Union, types.UnionType):
        kinds = [a for a in args if a is not type(None)]
        text = " or ".join(_name(a) for a in kinds)
        return f"{text} (optional)" if len(kinds) < len(args) else text
    if origin is Literal:
        return " or ".join(f'"{a}"' if isinstance(a, str) else str(a).lower() for a in args)
    if origin is tuple:
        return "[" + ", ".join(_name(a) for a in args) + "]"
    if origin is list:
        inner = args[0]
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return f"array of [{inner.__name__}](#{_anchor(inner)})"
        return f"list of ({_name(inner)})"
    if origin is dict:
        return "table"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return " or ".join(f'"{m.value}"' for m in tp)
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return f"[{tp.__name__}](#{_anchor(tp)})"
    if tp is Path:
        return "path"
    return getattr(tp, "__name__", str(tp))


def _anchor(model: type[BaseModel]) -> str:
    return model.__name__.lower()


def _default(field: FieldInfo) -> str:
    if field.is_required():
        return "required"
    value = field.get_default(call_default_factory=True)
    return f"`{_toml(value)}`" if value is not None else "unset"


def _toml(value: Any) -> str:
    if isinstance(value, enum.Enum):
        value = value.value
    if isinstance(value, BaseModel):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.model_dump(exclude_defaults=True).items()) + "}"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, Path):
        return f'"{value.as_posix()}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _bounds(field: FieldInfo) -> str:
    """The numeric bounds and pattern pydantic checks, as text."""
    out = []
    for m in field.metadata:
        for attr, sign in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"), ("min_length", "at least")):
            value = getattr(m, attr, None)
            if value is not None:
                out.append(f"{sign} {value}" if attr != "min_length" else f"at least {value} entries")
        if (pattern := getattr(m, "pattern", None)) is not None:
            out.append(f"matches `{pattern}`")
    return "; ".join(out)


def _table(model: type[BaseModel]) -> list[str]:
    rows = ["| key | type | default | description |", "|---|---|---|---|"]
    for key, field in model.model_fields.items():
        if field.exclude:
            continue
        text = " ".join((field.description or "").split())
        if bounds := _bounds(field):
            text = f"{text} ({bounds})" if text else bounds
        rows.append(f"| `{key}` | {_cell(_name(field.annotation))} | {_cell(_default(field))} | {_cell(text)} |")
    return rows


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return text.replace("|", "&#124;").replace("<", "&lt;")


def _sections() -> list[tuple[str, type[BaseModel], FieldInfo]]:
    """(TOML header, model, the field that holds it) of every section, nested ones after theirs."""
    out = []
    for key, field in Shot.model_fields.items():
        tp = field.annotation
        is_list = typing.get_origin(tp) is list
        inner = typing.get_args(tp)[0] if is_list else tp
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            out.append((f"[[{key}]]" if is_list else f"[{key}]", inner, field))
            for sub_key, sub in inner.model_fields.items():
                sub_tp = sub.annotation
                sub_inner = typing.get_args(sub_tp)[0] if typing.get_origin(sub_tp) is list else sub_tp
                if typing.get_origin(sub_tp) in (typing.Union, types.UnionType):  # an optional table
                    sub_inner = next(a for a in typing.get_args(sub_tp) if a is not type(None))
                if isinstance(sub_inner, type) and issubclass(sub_inner, BaseModel):
                    nested = f"[[{key}.{sub_key}]]" if typing.get_origin(sub_tp) is list else f"[{key}.{sub_key}]"
                    out.append((nested, sub_inner, sub))
    return out


def render() -> str:
    """docs/shots.md as text."""
    lines = [INTRO]
    for header, model, field in _sections():
        lines += [f'<a id="{_anchor(model)}"></a>', "", f"## `{header}`", ""]
        about = " ".join((field.description or "").split()) if header.count(".") == 0 else ""
        doc = inspect.cleandoc(model.__doc__ or "")
        for text in (about, " ".join(doc.split())):
            if text:
                lines += [text, ""]
        lines += _table(model) + [""]
    return "\n".join(lines).rstrip() + "\n"


def write(path: Path = DOC) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render())
    return path


def stale(path: Path = DOC) -> bool:
    """True when `path` differs from what `render()` makes now (or does not exist)."""
    return not path.is_file() or path.read_text() != render()


def main(*, check: bool) -> int:
    """`mpmfx docs`: write docs/shots.md, or (check) exit 1 naming the command when it is stale."""
    if check:
        if stale():
            print(f"{DOC} is stale: run `mpmfx docs --write` and commit it")
            return 1
        print(f"{DOC} is up to date")
        return 0
    print(f"wrote {write()}")
    return 0
