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


def test_a_variant_publishes_beside_the_hand_off_and_every_listing_names_its_overrides(tmp_path, monkeypatch, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    cache = ["--cache", str(tmp_path / "cache")]
    plain = tmp_path / "published" / "tiny"
    assert main(["run", str(shot), "--until", "export", "-q", *cache]) == 0
    handed_over = plain.resolve()
    variant = ["--set", "surface.smooth_iters=2"]
    assert main(["run", str(shot), "--until", "export", "-q", *variant, *cache]) == 0
    beside = tmp_path / "published" / "tiny@surface.smooth_iters=2"
    assert (beside / "shot.usda").is_file() and beside.resolve() != handed_over
    assert plain.resolve() == handed_over  # the hand-off is untouched
    capsys.readouterr()

    assert main(["status", str(shot), *variant, *cache]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[2:7]}
    assert rows["simulate"].endswith("(plain shot)")  # shared with the plain shot: it holds no override
    assert rows["surface"].endswith("--set surface.smooth_iters=2")
    assert rows["export"].endswith("--set surface.smooth_iters=2")
    assert main(["clean", str(shot), *variant, "--stage", "surface", "--dry-run", *cache]) == 0
    assert "would delete" in (out := capsys.readouterr().out) and "--set surface.smooth_iters=2" in out

    # asked for: the variant replaces the hand-off (and is published beside it as well)
    again = ["--set", "surface.smooth_iters=3", "--publish-as", "default"]
    assert main(["run", str(shot), "--until", "export", "-q", *again, *cache]) == 0
    assert plain.resolve() == (tmp_path / "published" / "tiny@surface.smooth_iters=3").resolve() != handed_over
    capsys.readouterr()
    assert main(["cache", "prune", "--keep", "1", "--dry-run", *cache]) == 0
    listed = [line for line in capsys.readouterr().out.splitlines() if "would delete" in line]
    assert listed and all(line.endswith(("(plain shot)", "--set surface.smooth_iters=2")) for line in listed)
    assert any(line.endswith("(plain shot)") for line in listed)  # the former hand-off's entries


def test_a_variant_name_is_readable_unique_and_a_valid_folder():
    from mpmfx.publish import publish_name

    def shot(*overrides):
        return SimpleNamespace(shot=SimpleNamespace(name="s"), overrides=overrides)

    assert publish_name(shot()) == "s"
    assert publish_name(shot("shot.name=s")) == "s"  # a renamed shot, not a variant
    assert publish_name(shot("domain.grid_n=48")) == "s@domain.grid_n=48"
    a, b = publish_name(shot("render.looks={a = 'x'}")), publish_name(shot("render.looks={a = 'y'}"))
    assert a != b and "/" not in a and " " not in a and a.startswith("s@render.looks=")
    long = publish_name(shot(*(f"objects.{i}.overrides.youngs_modulus={i}000" for i in range(9))))
    assert len(long) < 80 and long != publish_name(shot(*(f"objects.{i}.overrides.youngs_modulus=1" for i in range(9))))
