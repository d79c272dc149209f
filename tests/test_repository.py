"""The repository speaks of the product only, and every document it cites is in it.

- No history: how the project was built (working periods and their ordinals, leases, issue
  numbers, dated runs, run ordinals in file names) belongs in CHANGELOG.md and git, not in code,
  comments, docs or file names.
- Every cited document exists: paths under docs/, lab/, assets/, pipeline/, scripts/, mpmfx/,
  tests/ and renders/readme/, Markdown file names and relative Markdown links. Documents kept outside the repository
  are never cited.
- docs/images/ holds exactly the pictures the Markdown documents show.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()  # it spells the patterns out
TEXT = {".py", ".md", ".toml", ".sh", ".txt", ".csv", ".cfg", ".ini", ".yml", ".yaml", ".json", ".usda"}
OUTSIDE = ("DESIGN.md", "validation.md")  # documents that live outside the repository


def _tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [p for p in out.decode().split("\0") if p and (ROOT / p).is_file()]


def _text_files() -> dict[str, str]:
    """Tracked text files (path -> text), this file excepted."""
    out = {}
    for rel in _tracked():
        path = ROOT / rel
        if rel == THIS or not (path.suffix in TEXT or rel.startswith((".ci/", "ci/")) or path.name.startswith(".")):
            continue
        try:
            out[rel] = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
    return out


_ORDINALS = (
    "first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|thirteenth|"
    "fourteenth|fifteenth|sixteenth|seventeenth|eighteenth|nineteenth|twentieth"
)
HISTORY = {
    "a working period": re.compile(r"\bsessions?\b", re.I),
    "a lease": re.compile(r"\bleas(e|es|ed|ing)\b", re.I),
    "an issue number": re.compile(r"\bissues? #?\d+", re.I),
    # "the eighteenth" and its like number working periods; "first run" or "second pass" do not
    "an ordinal of a working period": re.compile(
        rf"\b({_ORDINALS})[- ](session|working period|lease)s?\b|\b({_ORDINALS.split('|tenth|')[1]})\b", re.I
    ),
    "a dated run": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
}
# Technical words that happen to match: pytest's fixture scope.
ALLOWED = re.compile(r"scope=[\"']session[\"']")


def _history(rel: str, text: str) -> list[str]:
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        line = ALLOWED.sub("", line)
        for what, pattern in HISTORY.items():
            if what == "a dated run" and rel == "CHANGELOG.md" and line.startswith("#"):
                continue  # a version heading carries its release date
            if m := pattern.search(line):
                found.append(f"{rel}:{n}: {what}: {m.group(0)!r}")
    return found


def test_no_history_in_text():
    bad = [hit for rel, text in _text_files().items() for hit in _history(rel, text)]
    assert not bad, (
        "how the project was built belongs in CHANGELOG.md and git, not here:\n"
        + "\n".join(bad[:80])
        + (f"\n... and {len(bad) - 80} more" if len(bad) > 80 else "")
    )


def test_no_history_in_file_names():
    dated = re.compile(r"20\d\d-?\d\d-?\d\d|_s\d+(?=[._-]|$)|\bsessions?\b", re.I)
    bad = [rel for rel in _tracked() if dated.search(Path(rel).name)]
    assert not bad, "file names carry a date or a run ordinal:\n" + "\n".join(bad)


# -- cited documents ---------------------------------------------------------------------------

CITED_PATH = re.compile(r"(?<![\w./~-])((?:docs|lab|assets|pipeline|scripts|mpmfx|tests|renders/readme)/[\w./-]*\w)")
CITED_MD = re.compile(r"(?<![\w./~-])([\w-]+\.md)\b")
MD_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)|<img[^>]*\bsrc=\"([^\"]+)\"")


def _is_template(text: str, end: int) -> bool:
    """A path pattern rather than a path: `pipeline/shots/*.toml`, `docs/{name}.md`, `frames/<n>`."""
    return text[end : end + 1] in ("*", "<", "{", "[") or text[end : end + 2] in ("/*", "/<", "/{", "/[")


PLACEHOLDER = re.compile(r"(^|/)(?!README\b|CHANGELOG\b|LICENSE\b)[A-Z][A-Z0-9_]*(\.\w+)?$")  # lab/NAME.py


def _cited_paths(text: str) -> set[str]:
    out = set()
    for m in CITED_PATH.finditer(text):
        path = m.group(1).rstrip(".")
        if not _is_template(text, m.end()) and not path.endswith((".", "/")) and not PLACEHOLDER.search(path):
            out.add(path)
    return out


def test_cited_paths_exist():
    tracked = set(_tracked())
    folders = {parent.as_posix() for p in tracked for parent in Path(p).parents}
    known = tracked | folders | {p[:-3] for p in tracked if p.endswith(".py")}  # a module, named without .py
    bad = [
        f"{rel}: cites {path}, which is not in the repository"
        for rel, text in _text_files().items()
        for path in sorted(_cited_paths(text))
        if path not in known
    ]
    assert not bad, "\n".join(bad)


def test_cited_markdown_documents_exist():
    names = {Path(p).name for p in _tracked()}
    bad = []
    for rel, text in _text_files().items():
        for name in sorted(set(CITED_MD.findall(text))):
            if name in OUTSIDE:
                bad.append(
                    f"{rel}: cites {name}, a document outside the repository: cite docs/architecture.md "
                    f"or docs/physics.md, or a public source by its title"
                )
            elif name not in names:
                bad.append(f"{rel}: cites {name}, which is not in the repository")
    assert not bad, "\n".join(bad)


def _md_targets(rel: str, text: str) -> list[Path]:
    """Relative link and image targets of a Markdown file, resolved against its folder."""
    out = []
    for m in MD_LINK.finditer(text):
        target = (m.group(1) or m.group(2)).split("#")[0]
        if not target or re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):
            continue  # an anchor in the same page, or a URL
        out.append((ROOT / rel).parent / target)
    return out


def test_markdown_links_resolve():
    bad = [
        f"{rel}: links to {t.relative_to(ROOT) if t.is_relative_to(ROOT) else t}, which does not exist"
        for rel, text in _text_files().items()
        if rel.endswith(".md")
        for t in _md_targets(rel, text)
        if not t.resolve().exists()
    ]
    assert not bad, "\n".join(bad)


def test_images_are_exactly_those_the_docs_show():
    images = ROOT / "docs" / "images"
    shown = {t.resolve() for rel, text in _text_files().items() if rel.endswith(".md") for t in _md_targets(rel, text)}
    kept = {(ROOT / p).resolve() for p in _tracked() if p.startswith("docs/images/")}
    uncited = sorted(p.relative_to(ROOT).as_posix() for p in kept - shown)
    missing = sorted(p.relative_to(ROOT).as_posix() for p in shown if p.is_relative_to(images) and not p.exists())
    assert not uncited, "docs/images/ holds pictures no document shows (delete them):\n" + "\n".join(uncited)
    assert not missing, "documents show pictures that docs/images/ lacks:\n" + "\n".join(missing)


def test_every_lab_script_has_its_line_in_the_lab_index():
    index = (ROOT / "lab" / "README.md").read_text()
    missing = [p.name for p in sorted((ROOT / "lab").glob("*.py")) if f"`{p.name}`" not in index]
    assert not missing, f"lab/README.md: add a line for {missing} (what it measures, which figure it makes)"
