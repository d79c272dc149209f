"""What artists look at is never lost: renders/ folders mpmfx did not make are refused before a
run, a wedge's sheets survive the shot's next publish, a killed publish is swept (or restored)
by the next run, and prune keeps what is published wherever it is run from."""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace

import pytest

from mpmfx.cache import PathError
from mpmfx.cli import main
from mpmfx.publish import check_publishable, publish_renders, published_entries, record, sweep
from tests.conftest import write_tiny_shot


def _render_entry(tmp_path: Path, frames=(1, 2)) -> SimpleNamespace:
    root = tmp_path / "cache" / "s" / "render" / "render-0123456789ab"
    (root / "frames").mkdir(parents=True)
    for f in frames:
        (root / "frames" / f"{f:04d}.png").write_bytes(b"png%d" % f)
    return SimpleNamespace(root=root, frames_dir=root / "frames")


def _shot(name: str = "s") -> SimpleNamespace:
    return SimpleNamespace(shot=SimpleNamespace(name=name), overrides=())


@pytest.mark.parametrize("name", ["readme", "check", "bench"])
def test_a_shot_named_after_a_folder_mpmfx_did_not_publish_is_refused_before_anything_runs(
    tmp_path, monkeypatch, capsys, name
):
    work = tmp_path / "work"
    (work / "renders" / name).mkdir(parents=True)
    keep = work / "renders" / name / "figure.png"
    keep.write_bytes(b"tracked")
    shot = write_tiny_shot(tmp_path)
    monkeypatch.chdir(work)
    code = main(["run", str(shot), "--set", f"shot.name={name}", "--cache", str(work / "cache")])
    assert code == 2
    err = capsys.readouterr().err
    assert "shot.name" in err and name in err
    assert keep.read_bytes() == b"tracked"
    assert not (work / "cache").exists()  # refused before any stage ran


def test_a_real_folder_at_the_published_link_is_refused(tmp_path):
    (tmp_path / "published" / "s").mkdir(parents=True)
    with pytest.raises(PathError, match="published"):
        check_publishable("s", renders=tmp_path / "renders", published=tmp_path / "published")


def test_a_real_folder_met_at_publish_time_is_bad_input_not_a_traceback(tmp_path):
    from mpmfx.publish import publish_stage

    (tmp_path / "published" / "s").mkdir(parents=True)  # made after the run's own check
    with pytest.raises(PathError, match="published/s exists"):
        publish_stage(_shot(), _render_entry(tmp_path), root=tmp_path / "published")


def test_a_wedge_outlives_the_shots_next_publish(tmp_path):
    renders = tmp_path / "renders"
    publish_renders(_shot(), _render_entry(tmp_path), root=renders)
    sheet = renders / "s" / "wedge-surface.radius_scale" / "contact.png"
    sheet.parent.mkdir()
    sheet.write_bytes(b"wedge")
    publish_renders(_shot(), _render_entry(tmp_path / "again", frames=(1, 2, 3)), root=renders)
    assert sheet.read_bytes() == b"wedge"
    assert sorted(p.name for p in (renders / "s").glob("*.png")) == ["0001.png", "0002.png", "0003.png"]
    check_publishable("s", renders=renders, published=tmp_path / "published")  # ours: may be replaced


def test_a_publish_killed_between_its_renames_is_restored_and_leftovers_swept(tmp_path):
    renders, published = tmp_path / "renders", tmp_path / "published"
    publish_renders(_shot(), _render_entry(tmp_path), root=renders)
    out = renders / "s"
    os.replace(out, renders / ".s.123-abcd.old")  # killed after the first rename ...
    (renders / ".s.123-abcd.tmp").mkdir()  # ... with a partial copy beside it
    published.mkdir()
    os.symlink("nowhere", published / ".s.123-abcd.tmp")
    sweep("s", renders=renders, published=published)
    assert (out / "published.json").is_file() and (out / "0002.png").read_bytes() == b"png2"
    assert sorted(p.name for p in renders.iterdir()) == ["s"]
    assert list(published.iterdir()) == []


def test_prune_from_another_directory_keeps_what_is_published(tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    export = cache / "s" / "export" / "export-0123456789ab"
    export.mkdir(parents=True)
    (tmp_path / "published").mkdir()
    link = tmp_path / "published" / "s"
    os.symlink(export, link)
    renders = tmp_path / "renders"
    entry = _render_entry(tmp_path)
    publish_renders(_shot(), entry, root=renders)
    record(cache / "s", {"usd": link / "shot.usda", "renders": renders / "s"})
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert published_entries(cache) == {export.resolve(), entry.root.resolve()}
    assert json.loads((cache / "s" / "published_to.json").read_text())["published"] == [
        str(link),
        str(renders / "s"),
    ]


def test_clean_removes_the_published_link_it_would_leave_dangling(tmp_path, monkeypatch, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    cache = str(tmp_path / "cache")
    assert main(["run", str(shot), "--until", "export", "--cache", cache, "-q"]) == 0
    link = tmp_path / "published" / "tiny"
    assert (link / "shot.usda").is_file()
    assert main(["clean", str(shot), "--stage", "export", "--yes", "--cache", cache]) == 0
    assert not link.is_symlink()
    assert "run the shot again to publish it" in capsys.readouterr().out


def test_a_shot_whose_renders_hold_only_its_wedges_may_publish(tmp_path):
    renders = tmp_path / "renders"
    (renders / "s" / "wedge-surface.radius_scale").mkdir(parents=True)
    check_publishable("s", renders=renders, published=tmp_path / "published")
    publish_renders(_shot(), _render_entry(tmp_path), root=renders)
    assert (renders / "s" / "wedge-surface.radius_scale").is_dir() and (renders / "s" / "published.json").is_file()
