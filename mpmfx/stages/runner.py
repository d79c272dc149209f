"""Runs the stages of one shot in order, each a cache hit or a (resumed) run.

`ShotRun` is the Python API behind `mpmfx run/status/clean`:
    mpmfx.load_shot("pipeline/shots/jelly_splash.toml").run(until="surface")
"""

from __future__ import annotations

import contextlib
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from mpmfx import checksum
from mpmfx.cache import Cache, DamagedError, Entry, code_hash, default_root, read_manifest, remove_temps
from mpmfx.config import Shot, ShotError
from mpmfx.publish import check_publishable, publish_name, publish_renders, publish_stage, record, sweep
from mpmfx.shotfile import load_shot_config
from mpmfx.stages import STAGES, export, memory, render, simulate, surface, voxelise
from mpmfx.stages.base import Context, Stage, StageError
from mpmfx.stages.colliders import check_collider_meshes
from mpmfx.stages.follow import FOLLOWED, Follower
from mpmfx.stages.kernels import GROUPS, ShotKernels
from mpmfx.stages.parallel import Frames
from mpmfx.stages.qa import shot_flags, warn_flags

PUBLISH_AS = ("variant", "default")  # where a --set run publishes: beside the hand-off, or also over it
MODULES: dict[str, Stage] = {m.NAME: m for m in (voxelise, simulate, surface, export, render)}
assert tuple(MODULES) == STAGES, "mpmfx.stages.STAGES and the runner's modules disagree"
PUBLISHED = ("export", "render")  # stages whose files a run publishes: verified byte for byte first


def stage_module(name: str) -> Stage:
    return MODULES[name]


@dataclass
class StageResult:
    stage: str
    state: str  # "cached" | "ran" | "resumed"
    seconds: float
    frames: int
    entry: Path
    flagged: int = 0  # frames the QA flags (simulate only)
    warnings: list[str] = field(default_factory=list)  # what the stage warned about (cached: when it ran)


@dataclass
class StageStatus:
    stage: str
    state: str  # "cached" | "stale" | "partial" | "missing"
    why: str
    entry: Path


class ShotRun:
    """One shot file bound to a cache root. Nothing runs until `run()`."""

    def __init__(
        self,
        shot: Shot,
        *,
        cache_root: str | Path | None = None,
        device: str | None = None,
        quiet: bool = False,
        workers: int | None = None,
        scheduler: str | None = None,
        executor: Frames | None = None,
        publish: bool = True,
        locked: bool = False,
        publish_as: str = "variant",
        overlap: bool = True,
    ):
        if publish_as not in PUBLISH_AS:
            raise ShotError(f"--publish-as {publish_as!r}: one of {', '.join(PUBLISH_AS)}")
        self.shot = shot
        self.cache = Cache(cache_root or default_root(), shot.shot.name)
        self.device = device
        self.quiet = quiet
        # Where independent frames run (mpmfx.stages.parallel): workers=1 serial, None auto.
        self._own_executor = executor is None
        self.executor = executor or Frames(workers=workers, scheduler=scheduler)
        self.publish = publish  # False for a wedge's variants: renders/ and published/ show the shot
        self.locked = locked  # the caller holds the shot's lock (a wedge, for all its variants)
        # published/<name> and renders/<name>: the variant's own name, and with "default" the
        # shot's own name as well (a variant then replaces the hand-off, as asked)
        self.publish_names = [publish_name(shot)]
        if publish_as == "default" and shot.shot.name not in self.publish_names:
            self.publish_names.append(shot.shot.name)
        self.published: dict[str, Path] = {}  # what the last run() published: "usd", "renders"
        self.overlap = overlap  # surface and export follow simulate frame by frame (stages.follow)

    # -- keys ------------------------------------------------------------------------------
    def entries(self) -> dict[str, Entry]:
        """Each stage's entry; keys chain, so a change upstream changes every key after it."""
        out: dict[str, Entry] = {}
        upstream: dict[str, str] = {}
        for name in STAGES:
            mod = stage_module(name)
            inputs = {"code": code_hash(mod.CODE), **mod.inputs(self.shot)}
            entry = self.cache.entry(name, mod.VERSION, mod.params(self.shot), dict(upstream), inputs)
            out[name] = entry
            upstream = {name: entry.key}
        return out

    def _wanted(self, name: str, frames: list[int] | None) -> list[int] | None:
        mod = stage_module(name)
        if not mod.PER_FRAME:
            return None
        all_frames = list(self.shot.frames)
        if name == "simulate" and frames:
            # the simulation is sequential: frames up to the last one asked for
            return [f for f in all_frames if f <= max(frames)]
        return frames or all_frames

    def entry_overrides(self, name: str) -> list[str]:
        """The --set overrides this run's entry of stage `name` holds: those without which its key
        would differ (a variant of a surfacing field shares the plain shot's simulation, whose
        entry holds none). What `status`, `clean` and `cache prune` show beside an entry."""
        overrides = list(self.shot.overrides)
        if not overrides or self.shot.source is None:
            return overrides
        key, out = self.entries()[name].key, []
        for i, o in enumerate(overrides):
            try:
                shot = load_shot_config(self.shot.source, overrides[:i] + overrides[i + 1 :])
                other = ShotRun(shot, cache_root=self.cache.root, executor=self.executor, publish=False)
                if other.entries()[name].key == key:
                    continue
            except ShotError:  # the others alone are no valid shot: this one counts
                pass
            out.append(o)
        return out

    # -- status ----------------------------------------------------------------------------
    def status(self) -> list[StageStatus]:
        out = []
        for name, entry in self.entries().items():
            if entry.complete(self._wanted(name, None)):
                host = (entry.manifest() or {}).get("host")
                other = f" (written on {host})" if host and host != socket.gethostname() else ""
                out.append(StageStatus(name, "cached", "all frames present" + other, entry.root))
            elif entry.root.exists():
                n = len(entry.done_frames(stage_module(name).FRAME_EXT))
                why = f"{n} frames done; a run resumes"
                if bad := entry.damaged():
                    why = f"{len(bad)} files lost or changed since written ({bad[0]}); a run redoes them"
                out.append(StageStatus(name, "partial", why, entry.root))
            elif others := [p for p in self.cache.entries(name) if p != entry.root]:
                newest = max(others, key=lambda p: p.stat().st_mtime)
                out.append(StageStatus(name, "stale", _why_stale(entry, newest), entry.root))
            else:
                out.append(StageStatus(name, "missing", "never run", entry.root))
        return out

    def verify(self) -> tuple[list[tuple[str, Path, str]], int]:
        """Read every file and checkpoint of every entry of this shot (every variant's) and
        compare each with the digest recorded when it was written (`status --verify`), under the
        shot's lock. A damaged file is marked, so its entry turns partial and the next run redoes
        it; a damaged checkpoint is deleted (a resume uses an earlier one). Returns
        ([(stage, path, why)], the number of files with no recorded digest: checked by size)."""
        out, unverified = [], 0
        if not self.cache.shot_dir.is_dir():
            return out, unverified  # nothing cached (and no shot folder made for its lock)
        with contextlib.nullcontext() if self.locked else self.cache.lock():
            for name, root in ((n, r) for n in STAGES for r in self.cache.entries(n) if _real_dir(r)):
                entry = Entry(root, name, root.name.rpartition("-")[2], {})
                man = entry.manifest() or {}
                changed, unknown = entry.verify()
                unverified += len(unknown)
                for rel in sorted(set(changed) | set(entry.damaged(man))):
                    out.append((name, entry.root / rel, _why_damaged(entry, man, rel)))
                    if rel.startswith("checkpoints/"):
                        checksum.forget(entry.root / rel)
                if files := [rel for rel in changed if not rel.startswith("checkpoints/")]:
                    entry.mark_damaged(files)
        return out, unverified

    # -- run -------------------------------------------------------------------------------
    def run(
        self, *, until: str = "render", force: tuple[str, ...] | list[str] = (), frames: list[int] | None = None
    ) -> list[StageResult]:
        """Run stages up to `until` (inclusive). `force`: stages re-run from scratch. Independent
        frames run on `self.executor` (a Dask cluster started when first worth it, closed here
        unless it was handed in). Holds the shot's lock throughout."""
        self.check(until=until, force=force, frames=frames)
        with contextlib.nullcontext() if self.locked else self.cache.lock():
            if not self.locked:
                self.cache.remove_orphans()
            if self.publish:
                for name in self.publish_names:
                    sweep(name)
            try:
                results = self._run_locked(until, force, frames)
            finally:
                if self._own_executor:
                    self.executor.close()
            self.published = self._publish(results) if self.publish else {}
        for r in results:
            if r.stage == "simulate":  # cached or not: bad physics is said every time
                bad = shot_flags(self.shot, (self.entries()["simulate"].manifest() or {}).get("qa", {}))
                warn_flags(bad, str(self.shot.source or "SHOT"))
                r.flagged = len(bad)
        return results

    def check(self, *, until: str = "render", force=(), frames: list[int] | None = None) -> None:
        """Refuse an unknown stage, a frame outside the shot (ShotError) or a shot whose publish
        would replace a folder mpmfx did not make (PathError): exit 2, before anything runs."""
        if self.publish:
            for name in self.publish_names:
                check_publishable(name)
        if getattr(self.executor, "scheduler", None):
            self.executor.client()  # a farm that does not answer is said now, not after simulate
        for name in (until, *force):
            if name not in STAGES:
                raise ShotError(f"unknown stage '{name}': one of {', '.join(STAGES)}")
        if frames:
            bad = sorted(set(frames) - set(self.shot.frames))
            if bad:
                raise ShotError(
                    f"--frames: {bad[0]} is outside the shot's frames "
                    f"{self.shot.shot.frame_start}..{self.shot.shot.frame_end}"
                )
        self.memory(until)

    def memory(self, until: str = "render") -> None:
        """State the memory the shot needs and refuse it (ShotError) over what the machine has
        (`mpmfx.stages.memory`): particles as voxelised when that is cached, else bounded from
        the objects' boxes."""
        entries = self.entries()
        if not entries["simulate"].complete():
            check_collider_meshes(self.shot)  # a bad collider asset: refused before voxelise runs
        vox = entries["voxelise"]
        if vox.complete():
            counted = memory.Counts(int((vox.manifest() or {}).get("particles", 0)))
        else:
            counted = memory.counts(self.shot)
        follows = self.overlap and STAGES.index(until) >= STAGES.index("surface") and not entries["simulate"].complete()
        memory.check(self.shot, counted, device=self.device, quiet=self.quiet, overlap=follows)

    def _publish(self, results: list[StageResult]) -> dict[str, Path]:
        """Every run that reaches export / render publishes them at stable paths (`mpmfx.publish`)."""
        entries, out = self.entries(), {}
        done = {r.stage for r in results}
        for i, name in enumerate(self.publish_names):
            suffix = "" if i == 0 else f" {name}"  # "usd", "renders": the variant's own name
            if "export" in done:
                out["usd" + suffix] = publish_stage(self.shot, entries["export"], name=name)
            if "render" in done:
                out["renders" + suffix] = publish_renders(self.shot, entries["render"], name=name)
        if out:
            record(self.cache.shot_dir, out)
        return out

    def _run_locked(self, until: str, force, frames: list[int] | None) -> list[StageResult]:
        """The stages in order. A file a stage reads that turns out changed since it was written
        (DamagedError) is marked in its entry, and the stages run again from the top: the one
        that wrote it redoes that file (its other frames are kept), the reader resumes."""
        redone: set[tuple[str, str]] = set()
        results: dict[str, StageResult] = {}
        while True:
            try:
                for r in self._stages(until, force, frames):  # a stage done on a pass before keeps its state
                    results[r.stage] = r if r.state != "cached" or r.stage not in results else results[r.stage]
                return [results[name] for name in STAGES[: STAGES.index(until) + 1]]
            except DamagedError as exc:
                if (exc.root, exc.rel) in redone:
                    raise StageError(
                        f"{exc}, again after it was redone: the disk (or memory) may be failing; "
                        f"check it, or point --cache at another disk"
                    ) from None
                redone.add((exc.root, exc.rel))
                self._mark(exc.root, [exc.rel], exc.why)
                force = ()  # done on the first pass; forcing again would drop the new frames

    def _mark(self, root: str, rels: list[str], why: str) -> None:
        """Mark damaged files of one of this shot's entries, saying so on stderr."""
        entry = next((e for e in self.entries().values() if str(e.root.resolve()) == str(Path(root).resolve())), None)
        if entry is None:
            raise StageError(f"{Path(root) / rels[0]}: {why}; it is no entry of this shot, so it is not redone")
        if not entry.mark_damaged(rels):  # no manifest to mark: the files are gone, so are their frames
            for rel in rels:
                _forget(entry, rel)
        more = f" (and {len(rels) - 1} more)" if len(rels) > 1 else ""
        print(f"[{entry.stage}] {entry.root / rels[0]}{more}: {why}; redoing it", file=sys.stderr)

    def _stages(self, until: str, force, frames: list[int] | None):
        """Each stage up to `until`: its result, as it finishes. While simulate runs, the surface
        and export stages follow it frame by frame (`mpmfx.stages.follow`)."""
        entries = self.entries()
        names = STAGES[: STAGES.index(until) + 1]
        for name in names:
            if name in force:  # before anything runs: a follower writes into later stages' entries
                entries[name].remove()
        surfacing = "surface" in names and not entries["surface"].complete(self._wanted("surface", frames))
        # the Warp modules of the stages that will launch kernels, compiled ahead from now (kernels.py)
        making = [s for s in GROUPS if s in names and not entries[s].complete(self._wanted(s, frames))]
        kernels = ShotKernels.for_run(self.shot, self.device, making).start()
        follower = None
        try:
            for name in names:
                if follower and name in follower.contexts:
                    ctx = follower.finish(name)  # (its error, if it had one, is this stage's)
                else:
                    ctx = self.begin(name, entries, frames)
                if isinstance(ctx, StageResult):
                    yield ctx
                    continue
                if name == "simulate" and surfacing and self.overlap:
                    follower = self._follow(names, entries, frames, kernels)
                kernels.wait(name)  # (a no-op but for the first run of a stage that launches kernels)
                t0 = time.perf_counter()
                with self.failing(ctx):
                    extra = stage_module(name).run(ctx) or {}
                if name == "simulate" and follower:
                    follower.upstream_done()
                if follower and name in follower.seconds:
                    extra["followed_s"] = {k: round(v, 3) for k, v in follower.seconds[name].items()}
                yield self.end(ctx, extra, time.perf_counter() - t0)
        finally:
            if follower:
                follower.stop()  # (a no-op wait when every followed stage has finished)
                for ctx in follower.contexts.values():
                    if ctx.entry.root.exists() and not ctx.entry.manifest():
                        self.abandon(ctx)  # a failed run: keep the frames it made, drop an empty entry

    def _follow(self, names, entries: dict[str, Entry], frames: list[int] | None, kernels) -> Follower | None:
        """A follower for the stages after simulate that this run makes (surface, and export
        when asked for), started; None when there is none to follow."""
        contexts = {}
        for name in FOLLOWED:
            if name not in names:
                break
            ctx = self.begin(name, entries, frames)
            if isinstance(ctx, StageResult):
                break
            contexts[name] = ctx
        return Follower(contexts, kernels=kernels).start() if contexts else None

    def begin(self, name: str, entries: dict[str, Entry], frames: list[int] | None) -> Context | StageResult:
        """A cached stage's result, or the context to run it in (damaged files removed, so their
        frames are redone; the entry folder made). Call with the shot's lock held."""
        entry, wanted = entries[name], self._wanted(name, frames)
        if self.publish and name in PUBLISHED and entry.root.is_dir():
            # what a publish hands on is read through: a changed file is redone, never published
            if bad := entry.verify(list(entry.files()))[0]:
                self._mark(str(entry.root), bad, "its bytes differ from those written (checksum)")
        if entry.complete(wanted):
            said = list((entry.manifest() or {}).get("warnings", []))
            return StageResult(name, "cached", 0.0, len(wanted) if wanted is not None else 1, entry.root, warnings=said)
        for rel in entry.damaged():  # lost, truncated or changed since written: redo, never trust
            _forget(entry, rel)
        state = "resumed" if entry.root.exists() else "ran"
        up = {s: entries[s] for s in STAGES[: STAGES.index(name)]}
        ctx = Context(
            self.shot,
            entry,
            up,
            wanted if wanted is not None else [],
            self.device,
            self.quiet,
            executor=self.executor,
            state=state,
        )
        entry.root.mkdir(parents=True, exist_ok=True)
        return ctx

    @contextlib.contextmanager
    def failing(self, ctx: Context):
        """Complete frames stay when a stage fails (a re-run resumes from them); an entry with none
        is removed, so a failed run never leaves a half-made cache entry behind."""
        try:
            yield
        except BaseException:
            self.abandon(ctx)
            raise

    def abandon(self, ctx: Context) -> None:
        """After a failure: keep complete frames, remove a new entry that has none."""
        mod = stage_module(ctx.entry.stage)
        if ctx.state == "ran" and not (mod.PER_FRAME and ctx.entry.done_frames(mod.FRAME_EXT)):
            ctx.entry.remove()

    def end(self, ctx: Context, extra: dict, seconds: float) -> StageResult:
        """After every task of the stage: temps of killed workers swept, then the manifest (the
        client writes it), listing only frames that exist."""
        entry, mod = ctx.entry, stage_module(ctx.entry.stage)
        remove_temps(entry.root)
        done = entry.done_frames(mod.FRAME_EXT) if mod.PER_FRAME else []
        missing = sorted(set(ctx.frames) - set(done)) if mod.PER_FRAME else []
        if missing:
            raise StageError(
                f"{entry.stage}: frames {_ranges(missing)} are missing after the run (deleted by "
                f"someone else?); no manifest written, run again to redo them"
            )
        old = entry.manifest() or {}
        timings = {**old.get("timings", {}), "last_run_s": round(seconds, 3)}
        entry.write_manifest(
            frames=done,
            timings=timings,
            qa=extra.pop("qa", None),
            extra={
                **extra,
                "notes": ctx.notes,
                "warnings": ctx.warnings,
                "host": socket.gethostname(),
                "overrides": self.entry_overrides(entry.stage),
            },
        )
        n = len(ctx.frames) if mod.PER_FRAME else 1
        return StageResult(entry.stage, ctx.state, seconds, n, entry.root, warnings=list(ctx.warnings))


def _real_dir(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink()  # (a link would send the marks outside the cache)


def _why_damaged(entry: Entry, man: dict, rel: str) -> str:
    path, size = entry.root / rel, {**man.get("files", {}), **man.get("checkpoints", {})}.get(rel)
    if rel.startswith("checkpoints/"):
        return "differs from what was written; deleted (a resume uses an earlier checkpoint, or the start)"
    if not path.is_file():
        return "missing; a run redoes it"
    if size is not None and path.stat().st_size != size:
        return f"{path.stat().st_size} bytes, {size} when written; a run redoes it"
    return "its bytes differ from those written (checksum); a run redoes it"


def _forget(entry: Entry, rel: str) -> None:
    """Delete a damaged file of `entry` and, in a per-frame stage, its frame's file, so the
    stage redoes that frame (e.g. vdb/g/0003.vdb: frames/0003.usdc goes too)."""
    mod = stage_module(entry.stage)
    checksum.forget(entry.root / rel)
    if mod.PER_FRAME and Path(rel).stem.isdigit():
        checksum.forget(entry.frame_path(int(Path(rel).stem), mod.FRAME_EXT))


def _ranges(frames: list[int]) -> str:
    """[1,2,3,7] -> '1-3, 7'."""
    out, start = [], frames[0]
    for a, b in zip(frames, frames[1:] + [None]):
        if b != a + 1:
            out.append(f"{start}-{a}" if a != start else str(a))
            start = b
    return ", ".join(out)


def _why_stale(entry: Entry, other: Path) -> str:
    """Name the key inputs that differ from the newest other entry of the same stage."""
    old = (read_manifest(other) or {}).get("key_inputs")
    if old is None:
        return "parameters or inputs changed"
    new = entry.key_inputs
    changed = []
    for group in ("version", "params", "upstream", "inputs"):
        a, b = old.get(group), new.get(group)
        if isinstance(a, dict) and isinstance(b, dict):
            changed += [f"{group}.{k}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            changed.append(group)
    return "changed: " + ", ".join(changed[:6]) if changed else "parameters or inputs changed"


def load_shot(
    path: str | Path,
    *,
    overrides: list[str] = (),
    cache_root: str | Path | None = None,
    device: str | None = None,
    quiet: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    publish_as: str = "variant",
    overlap: bool = True,
) -> ShotRun:
    """Load and validate a shot file; returns a ShotRun (see module docstring). workers /
    scheduler: where independent frames run (`mpmfx.stages.parallel.Frames`); publish_as:
    "variant" (a --set run publishes beside the plain shot's outputs) or "default" (also over them);
    overlap: surface and export follow simulate frame by frame (`mpmfx.stages.follow`)."""
    return ShotRun(
        load_shot_config(path, list(overrides)),
        cache_root=cache_root,
        device=device,
        quiet=quiet,
        workers=workers,
        scheduler=scheduler,
        publish_as=publish_as,
        overlap=overlap,
    )
