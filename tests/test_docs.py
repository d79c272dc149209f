"""docs/shots.md is the schema's own reference: generated from mpmfx/config.py, never stale."""

from __future__ import annotations

from pathlib import Path

from mpmfx import shotdoc
from mpmfx.config import Shot


def test_shot_reference_is_current():
    assert not shotdoc.stale(), "docs/shots.md is stale: run `mpmfx docs --write` and commit it"


def test_every_field_is_described():
    text = shotdoc.render()
    for header, model, _ in shotdoc._sections():
        assert f"## `{header}`" in text
        for key, field in model.model_fields.items():
            if not field.exclude:
                assert field.description, f"{model.__name__}.{key} has no description: add Field(description=...)"
                assert f"| `{key}` |" in text
    for key, field in Shot.model_fields.items():
        if not field.exclude:
            assert field.description, f"Shot.{key} has no description"


def test_write_makes_a_stale_file_current(tmp_path):
    stale = tmp_path / "shots.md"
    stale.write_text("old\n")
    assert shotdoc.stale(stale)
    shotdoc.write(stale)
    assert not shotdoc.stale(stale)


def test_docs_command_does_not_start_warp():
    import subprocess
    import sys

    code = (
        "import sys; from mpmfx.cli import main; rc = main(['docs', '--check']); "
        "assert 'warp' not in sys.modules; sys.exit(rc)"
    )
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    assert out.returncode == 0, out.stdout + out.stderr
