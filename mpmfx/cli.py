"""`mpmfx` command line. Parses, then calls the stage runner; imports nothing heavy at start-up
(warp, pxr, the schema's pydantic: the imports marked "keeps --help light" load them on use).

Exit codes: 0 success, 1 a stage failed (or a check failed), 2 bad input (config, file, arguments).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path

from mpmfx import __version__
from mpmfx.bench import main as bench_main
from mpmfx.cache import BusyError, Cache, DamagedError, Entry, PathError, default_root
from mpmfx.cli_args import add_parallel_args, add_wedge_parser, frame_range
from mpmfx.diskspace import DENIED, FULL, message
from mpmfx.maintain import clean_targets, delete, human, prune_targets, tree_size
from mpmfx.publish import drop_dangling, published_entries
from mpmfx.stages import STAGES
from mpmfx.stages.qa import print_qa


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="mpmfx", description="Meshes to simulated, surfaced and rendered MPM snow, sand, mud, water and jelly."
    )
    p.add_argument("--version", action="version", version=f"mpmfx {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")

    def shot_cmd(name, help_):
        s = sub.add_parser(name, help=help_, description=help_)
        s.add_argument("shot", help="shot file, e.g. pipeline/shots/jelly_splash.toml")
        s.add_argument(
            "--set",
            dest="overrides",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="override any shot field, e.g. --set solver.cfl=0.3 --set objects.0.material=Water",
        )
        s.add_argument("--cache", default=None, help="cache root (default $MPMFX_CACHE or ./cache)")
        return s

    r = shot_cmd("run", "run the pipeline (cached stages are skipped)")
    r.add_argument("--until", choices=STAGES, default="render", help="last stage to run")
    r.add_argument("--force", choices=STAGES, action="append", default=[], help="re-run this stage from scratch")
    r.add_argument("--frames", type=frame_range, default=None, metavar="A:B", help="only these frames (inclusive)")
    r.add_argument("--device", choices=("cpu", "cuda"), default=None, help="Warp device (default: cuda if present)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    r.add_argument("--strict", action="store_true", help="exit 1 when the QA flags a frame (CI, farms)")
    r.add_argument(
        "--no-overlap",
        dest="overlap",
        action="store_false",
        help="run the stages one after another (default: surface and export follow simulate frame by frame)",
    )
    e = shot_cmd("export", "run export alone from the cached upstream stages")
    e.add_argument("--frames", type=frame_range, default=None, metavar="A:B")
    add_parallel_args(r)
    add_parallel_args(e)
    for cmd in (r, e):
        cmd.add_argument(
            "--publish-as",
            choices=("variant", "default"),
            default="variant",
            help="where a --set run publishes: variant (default): published/SHOT@OVERRIDES and "
            "renders/SHOT@OVERRIDES, beside the hand-off; default: also over published/SHOT and renders/SHOT",
        )
    add_wedge_parser(shot_cmd("wedge", "side-by-side variants of a shot that differ in one field"))
    s = shot_cmd("status", "each stage: cached, partial, stale or missing, and why")
    s.add_argument("--qa", action="store_true", help="per-frame observables of the simulation")
    s.add_argument(
        "--verify",
        action="store_true",
        help="read every cached file and compare it with its checksum; exit 1 naming the damaged "
        "ones (marked: the next run redoes them)",
    )
    c = shot_cmd("clean", "delete this variant's cached results (listed with sizes first)")
    c.add_argument("--stage", choices=STAGES, default=None, help="only this stage (default: every stage)")
    c.add_argument("--all-variants", action="store_true", help="every variant's entries, not only this one's")
    c.add_argument("--dry-run", action="store_true", help="list what would be deleted, delete nothing")
    c.add_argument("-y", "--yes", action="store_true", help="delete a simulation without asking")

    m = sub.add_parser("cache", help="cache housekeeping")
    m.add_argument("action", choices=("prune",), help="prune: delete old variants (listed with sizes first)")
    m.add_argument(
        "--keep",
        type=int,
        default=2,
        metavar="N",
        help="newest variants kept per shot and stage (entries a published output uses are always kept)",
    )
    m.add_argument("--cache", default=None, help="cache root (default $MPMFX_CACHE or ./cache)")
    m.add_argument("--dry-run", action="store_true", help="list what would be deleted, delete nothing")
    m.add_argument("-y", "--yes", action="store_true", help="delete simulations without asking")

    d = sub.add_parser("docs", help="write docs/shots.md, the shot field reference, from the schema")
    d.add_argument("--check", action="store_true", help="write nothing; exit 1 when docs/shots.md is stale")
    d.add_argument("--write", action="store_true", help="write it (the default)")

    k = sub.add_parser(
        "check",
        help="five-cell thickness check of an asset or a shot's objects (exit 0 pass/warn, 1 fail, 2 bad input)",
    )
    k.add_argument(
        "asset",
        help="a shot (.toml: each of its objects, placed and at the shot's grid) or a mesh file "
        "(obj, ply, stl, glb, gltf, usd, usda, usdc, usdz, blend, fbx)",
    )
    k.add_argument(
        "--grid-n", type=int, default=None, help="grid cells per axis of the domain (default: the shot's, or 64)"
    )
    k.add_argument(
        "--domain",
        default=None,
        metavar="OX,OY,OZ,SIZE",
        help="domain min corner and edge (m); default: the mesh's bounding cube + 10 %%",
    )
    k.add_argument(
        "--prim-path",
        default=None,
        metavar="PART",
        help="check one part: a USD prim, or a .blend / .fbx object or collection name",
    )
    k.add_argument("--json", action="store_true", help="JSON for pipelines")

    b = sub.add_parser("bench", help="speed and accuracy benchmarks (run them on the GPU)")
    b.add_argument(
        "what",
        choices=(
            "accuracy",
            "oscillation",
            "gpu",
            "surface",
            "surface-times",
            "solver",
            "voxelise",
            "shots",
            "shot",
            "collapse",
        ),
        help="which benchmark",
    )
    b.add_argument("shot", nargs="?", default=None, help="shot: the shot file to run (default: the default shot)")
    b.add_argument("--quick", action="store_true", help="small CPU-sized sweep")
    b.add_argument("--device", choices=("cpu", "cuda"), default=None)
    b.add_argument("--out", default="renders/bench", help="folder for CSV/JSON/PNG")
    b.add_argument(
        "--peers",
        nargs="*",
        default=None,
        metavar="PEER",
        help="surface: other surfacers on the same particles, any of splashsurf newton "
        "newton-aniso; bare --peers runs none (default: all installed; --quick: splashsurf); "
        "surface-times: splashsurf (default: with --quick only)",
    )
    b.add_argument(
        "--counts",
        type=int,
        nargs="+",
        default=None,
        metavar="N",
        help="surface: particle counts (default 100000 with --quick, else 1000000 10000000); "
        "surface-times: likewise (default 100000 with --quick, else 10000000)",
    )
    b.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help="shot: override a shot field"
    )
    b.add_argument("--cache", default=None, help="shot: a cache root to run in and keep (default: a temporary one)")
    b.add_argument("--no-overlap", dest="overlap", action="store_false", help="shot: run the stages one after another")
    b.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=None,
        metavar="N",
        help="collapse: grid resolutions (default 32 64 128; --quick: 16 24 32)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return _dispatch(args)
    except KeyboardInterrupt:
        print("interrupted: complete frames are cached; run again to resume", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - every error becomes a message and an exit code
        from mpmfx.config import ShotError  # backend: pydantic (keeps --help light)
        from mpmfx.stages.base import StageError  # backend: warp (keeps --help light)
        from mpmfx.stages.parallel import TaskError  # backend: pydantic (keeps --help light)

        if isinstance(exc, (ShotError, PathError)):
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if isinstance(exc, (StageError, TaskError, BusyError)):
            print(f"error: {exc}", file=sys.stderr)
            return 1
        if isinstance(exc, DamagedError):  # (a run redoes it at once; here from a wedge's variants)
            Entry(Path(exc.root), "", "", {}).mark_damaged([exc.rel])
            print(f"error: {exc}; marked as damaged: run again to redo it", file=sys.stderr)
            return 1
        if isinstance(exc, OSError) and (exc.filename or exc.errno in (*FULL, *DENIED)):
            # a full disk or a folder not writable is the user's to fix (exit 2), said as the
            # path being written and the fix; another file system error is a failed stage
            cache_root = getattr(args, "cache", None) or default_root()
            print(f"error: {message(exc, cache_root=cache_root)}", file=sys.stderr)
            return 2 if exc.errno in (*FULL, *DENIED) else 1
        raise


def _dispatch(args) -> int:
    if args.cmd == "check":
        from mpmfx.check import run_check, run_shot_check  # backend: trimesh (keeps --help light)

        if args.asset.endswith(".toml"):
            if args.domain or args.prim_path:
                print(
                    f"error: {args.asset} is a shot: its domain and its objects' parts come from it; "
                    "leave out --domain and --prim-path (or check one asset: mpmfx check MESH)",
                    file=sys.stderr,
                )
                return 2
            return run_shot_check(args.asset, grid_n=args.grid_n, as_json=args.json)
        origin = size = None
        if args.domain:
            try:
                *o, s = (float(x) for x in args.domain.split(","))
                assert len(o) == 3 and all(math.isfinite(v) for v in (*o, s)) and s > 0
            except (ValueError, AssertionError):
                print(
                    f"error: --domain {args.domain!r}: expected OX,OY,OZ,SIZE in metres, finite numbers, "
                    f"SIZE above 0, e.g. --domain=-0.5,0,-0.5,1",
                    file=sys.stderr,
                )
                return 2
            origin, size = tuple(o), s
        return run_check(
            args.asset,
            grid_n=64 if args.grid_n is None else args.grid_n,
            origin=origin,
            size=size,
            as_json=args.json,
            prim_path=args.prim_path,
        )
    if args.cmd == "bench":
        from mpmfx.stages.base import quiet_warp  # backend: warp (keeps --help light)

        quiet_warp()  # stdout carries the benchmark's tables only, never Warp's banner
        return bench_main(
            args.what,
            quick=args.quick,
            device=args.device,
            out=args.out,
            peers=args.peers,
            counts=args.counts,
            shot=args.shot,
            overrides=args.overrides,
            cache=args.cache,
            overlap=args.overlap,
            sizes=args.sizes,
        )

    if args.cmd == "cache":
        return _prune(args)
    if args.cmd == "docs":
        from mpmfx.shotdoc import main as docs_main  # backend: pydantic (keeps --help light)

        return docs_main(check=args.check)
    if args.cmd == "wedge":
        from mpmfx.wedge import main as wedge_main  # backend: warp (keeps --help light)

        return wedge_main(args)

    from mpmfx.stages.runner import load_shot  # backend: warp (keeps --help light)

    run = load_shot(
        args.shot,
        overrides=args.overrides,
        cache_root=args.cache,
        device=getattr(args, "device", None),
        quiet=getattr(args, "quiet", False),
        workers=getattr(args, "workers", None),
        scheduler=getattr(args, "scheduler", None),
        publish_as=getattr(args, "publish_as", "variant"),
        overlap=getattr(args, "overlap", True),
    )
    if args.cmd == "run":
        results = run.run(until=args.until, force=args.force, frames=args.frames)
        _print_table(
            ["stage", "result", "wall s", "frames", "qa"],
            [
                [
                    r.stage,
                    r.state,
                    f"{r.seconds:.1f}",
                    str(r.frames),
                    f"{r.flagged} frame{'s' * (r.flagged != 1)} flagged" if r.flagged else "",
                ]
                for r in results
            ],
        )
        _print_warnings(results)
        _print_outputs(run, results)
        flagged = sum(r.flagged for r in results)
        if flagged and args.strict:
            print(f"error: --strict: the QA flags {flagged} frame(s) (see above)", file=sys.stderr)
            return 1
        return 0
    if args.cmd == "export":
        results = run.run(until="export", frames=args.frames)
        missing = [r.stage for r in results[:-1] if r.state != "cached"]
        if missing:
            print(f"note: export needed upstream stages first and ran them: {', '.join(missing)}", file=sys.stderr)
        _print_outputs(run, results)
        return 0
    if args.cmd == "status":
        damaged, unverified = run.verify() if args.verify else ([], 0)
        rows = [
            [
                s.stage,
                s.state,
                s.why,
                human(tree_size(s.entry)) if s.entry.exists() else "",
                os.path.relpath(s.entry),
                " ".join(f"--set {o}" for o in run.entry_overrides(s.stage)) or "(plain shot)",
            ]
            for s in run.status()
        ]
        _print_table(["stage", "state", "why", "disk", "entry", "overrides"], rows)
        shot_dir = run.cache.shot_dir
        if shot_dir.is_dir():
            print(
                f"\nall variants of this shot: {human(tree_size(shot_dir))} in {os.path.relpath(shot_dir)} "
                f"(`mpmfx clean SHOT --all-variants` or `mpmfx cache prune` to free it)"
            )
        if args.verify:
            _print_verified(damaged, unverified)
        if args.qa and print_qa(run):
            return 1
        return 1 if damaged else 0
    if args.cmd == "clean":
        with run.cache.lock():
            targets = clean_targets(run, stage=args.stage, all_variants=args.all_variants)
            code = delete(targets, root=run.cache.root, dry_run=args.dry_run, yes=args.yes)
            for link in drop_dangling(run.cache.shot_dir) if code == 0 and not args.dry_run else []:
                print(f"removed {link}: its export entry was deleted; run the shot again to publish it")
            return code
    raise AssertionError(args.cmd)


def _prune(args) -> int:
    """`mpmfx cache prune`: every shot of the cache root, each under its lock."""
    root = Path(args.cache) if args.cache else default_root()
    if args.keep < 1:
        print("error: --keep must be at least 1 (clean SHOT --all-variants deletes everything)", file=sys.stderr)
        return 2
    if not root.is_dir():
        print(f"nothing to prune: no cache at {root}")
        return 0
    with contextlib.ExitStack() as locks:
        for shot_dir in sorted(p for p in root.iterdir() if p.is_dir()):
            locks.enter_context(Cache(root, shot_dir.name).lock())
        targets = prune_targets(root, keep=args.keep, in_use=published_entries(root))
        return delete(targets, root=root, dry_run=args.dry_run, yes=args.yes)


def _print_verified(damaged: list, unverified: int) -> None:
    """`status --verify`: each damaged file and why, or that every file checked out."""
    print()
    if damaged:
        print(f"verify: {len(damaged)} damaged file{'s' * (len(damaged) != 1)}:")
        for stage, path, why in damaged:
            print(f"  {stage:<9} {os.path.relpath(path)}: {why}")
    else:
        print("verify: every cached file holds the bytes written")
    if unverified:
        print(
            f"verify: {unverified} file{'s' * (unverified != 1)} without a checksum (cached by an older "
            f"mpmfx): checked by size only"
        )


def _print_warnings(results) -> None:
    """Below the closing table, what the stages warned about while their bars ran (or, for a
    cached stage, when it ran): the warnings a user must not miss in the scroll."""
    said = [(r.stage, w) for r in results for w in r.warnings]
    if said:
        print("\nwarnings:")
        for stage, w in said:
            print(f"  [{stage}] {w}")


def _print_outputs(run, results) -> None:
    """Where every output of this run is: the stable published paths, then the cache entries."""
    entries = {r.stage: r.entry for r in results}
    print()
    for key, path in run.published.items():
        if key.startswith("usd"):
            print(f"USD + VDB  {path}  (-> {os.path.relpath(entries['export'])})")
        else:
            print(f"renders    {path}/  (-> {os.path.relpath(entries['render'])})")
    for stage in ("simulate", "surface"):
        if stage in entries:
            print(f"{stage:<9}  {os.path.relpath(entries[stage])}/frames/")


def _print_table(header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    for r in [header, ["-" * w for w in widths], *rows]:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip())


if __name__ == "__main__":
    sys.exit(main())
