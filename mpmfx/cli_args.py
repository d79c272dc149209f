"""Argument types and option groups of the command line, shared by `mpmfx.cli` and `mpmfx.wedge`.

Imported when the CLI starts: the standard library only.
"""

from __future__ import annotations

import argparse


def frame_range(text: str) -> list[int]:
    """--frames A:B (inclusive) -> [A, ..., B]; argparse.ArgumentTypeError on bad text."""
    try:
        a, _, b = text.partition(":")
        lo, hi = int(a), int(b or a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--frames {text!r}: expected A:B (inclusive), e.g. --frames 10:20") from None
    if hi < lo:
        raise argparse.ArgumentTypeError(f"--frames {text!r}: B must not be below A")
    return list(range(lo, hi + 1))


def _workers(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"--workers {text!r}: a whole number of processes, 1 or more (1 = serial)")
    return int(text)


def add_parallel_args(p) -> None:
    p.add_argument(
        "--workers",
        type=_workers,
        default=None,
        metavar="N",
        help="Dask LocalCluster worker processes for independent frames; 1 = serial "
        "(default: all cores when there are 10 or more frames to make, else serial; $MPMFX_WORKERS); "
        "Cycles frames go to workers only when N >= 2 or a scheduler is given",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="a running Dask scheduler, e.g. tcp://farm-head:8786 (default $MPMFX_SCHEDULER)",
    )


def add_wedge_parser(w) -> None:
    w.add_argument(
        "--vary",
        required=True,
        metavar="KEY=V1,V2,..|KEY=LO:HI:N",
        help="the one field to vary (any key --set takes; list items also by name, e.g. "
        "objects.bear.overrides.youngs_modulus) and its values",
    )
    w.add_argument("--log", action="store_true", help="LO:HI:N steps evenly in log space")
    w.add_argument(
        "--keep",
        default=None,
        metavar="PATH",
        help="the previous champion's render for the first tile: a folder of NNNN.png or one image",
    )
    w.add_argument(
        "--pick",
        default=None,
        metavar="VALUE",
        help="run nothing: write a copy of the shot file with KEY = VALUE (see --out)",
    )
    w.add_argument(
        "--out",
        default=None,
        metavar="PATH",
        help="--pick: the copy's path (default beside the shot: NAME-FIELD-VALUE.toml)",
    )
    w.add_argument("--frames", default=None, metavar="A:B", help="only these frames (inclusive)")
    w.add_argument("--device", choices=("cpu", "cuda"), default=None, help="Warp device")
    w.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    add_parallel_args(w)
