"""Rank a kernel's source lines from Nsight Compute's source page (development aid, issue 14).

On the GPU machine, with the kernels built with line info (Warp maps them to our Python lines):

    ncu --clock-control none -k regex:'g2p|scatter' --launch-skip 24 --launch-count 2 \
        --import-source yes --section SourceCounters --section WarpStateStats -o rep \
        python3 scripts/layout_probe.py --ncu --scene Mushy --grid 256 --lineinfo
    ncu -i rep.ncu-rep --page source --csv --print-source cuda,sass > src.csv

then anywhere:

    python3 scripts/ncu_lines.py src.csv scatter [--by stall|inst|local|global] [--top 25]

prints, for the first profiled kernel whose name contains the given text: its share of stall
samples and instructions per file (our modules and Warp's headers), the stall reasons, and the
top lines with their local-memory (spill) and global L2 sectors. How the 2026-11-26 scatter's
W in local memory and G2P's costly affine sum were found.
"""
from __future__ import annotations

import argparse
import collections
import csv


def sections(path: str) -> list[dict]:
    """The CSV's (file, function) sections: their header and per-line rows (SASS rows dropped)."""
    out, cur = [], None
    for row in csv.reader(open(path, newline="")):
        if len(row) == 2 and row[0] == "File Path":
            cur = {"file": row[1], "fn": "", "hdr": None, "rows": []}
            out.append(cur)
        elif len(row) == 2 and row[0] == "Function Name" and cur is not None:
            cur["fn"] = row[1]
        elif cur is not None and cur["hdr"] is None:
            cur["hdr"] = row
        elif cur is not None and row and row[0]:
            cur["rows"].append(row)
    return out


def num(v: str) -> float:
    try:
        return float(v.replace(",", ""))
    except ValueError:
        return 0.0


def lines(path: str, kernel: str) -> list[dict]:
    """Per source line of the first profiled kernel matching `kernel`: stall samples, warp
    instructions, L2 sectors (global, ideal, local) and the stall reasons."""
    out, seen = [], set()
    for s in sections(path):
        if kernel not in s["fn"] or s["file"] in seen or s["hdr"] is None:
            continue
        seen.add(s["file"])  # a second launch of the same kernel repeats its files
        h = s["hdr"]
        col = {name: h.index(name) for name in ("Warp Stall Sampling (All Samples)", "Instructions Executed",
                                                 "L2 Theoretical Sectors Global", "L2 Theoretical Sectors Local")}
        reasons = [c for c in h if c.startswith("stall_") and "Not Issued" not in c]
        for r in s["rows"]:
            out.append({"file": s["file"].rsplit("/", 1)[-1], "line": r[0], "src": r[1].strip()[:70],
                        "stall": num(r[col["Warp Stall Sampling (All Samples)"]]),
                        "inst": num(r[col["Instructions Executed"]]),
                        "global": num(r[col["L2 Theoretical Sectors Global"]]),
                        "local": num(r[col["L2 Theoretical Sectors Local"]]),
                        "reasons": {c[6:]: num(r[h.index(c)]) for c in reasons}})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv")
    ap.add_argument("kernel", help="text in the kernel's name, e.g. scatter or g2p")
    ap.add_argument("--by", choices=("stall", "inst", "local", "global"), default="stall")
    ap.add_argument("--top", type=int, default=25)
    a = ap.parse_args()
    rows = lines(a.csv, a.kernel)
    if not rows:
        raise SystemExit(f"{a.csv}: no profiled kernel named like {a.kernel!r}")
    stall = sum(r["stall"] for r in rows) or 1.0
    inst = sum(r["inst"] for r in rows) or 1.0
    print(f"{a.kernel}: {stall:.0f} stall samples, {inst:.3g} warp instructions, L2 sectors global "
          f"{sum(r['global'] for r in rows) / 1e6:.0f}M, local {sum(r['local'] for r in rows) / 1e6:.0f}M")
    per_file, per_file_inst, why = collections.Counter(), collections.Counter(), collections.Counter()
    for r in rows:
        per_file[r["file"]] += r["stall"]
        per_file_inst[r["file"]] += r["inst"]
        why.update(r["reasons"])
    for f, v in per_file.most_common():
        print(f"  {f:40s} stall {100 * v / stall:5.1f} %  instructions {100 * per_file_inst[f] / inst:5.1f} %")
    print("  stall reasons:", ", ".join(f"{k} {100 * v / stall:.1f} %" for k, v in why.most_common(8)))
    for r in sorted(rows, key=lambda r: -r[a.by])[:a.top]:
        top = sorted(r["reasons"].items(), key=lambda kv: -kv[1])[:2]
        print(f"stall {100 * r['stall'] / stall:4.1f} %  inst {100 * r['inst'] / inst:4.1f} %  "
              f"local {r['local'] / 1e6:6.1f}M  global {r['global'] / 1e6:6.1f}M  {r['file']}:{r['line']}  {r['src']}  "
              + ", ".join(f"{k} {v:.0f}" for k, v in top))


if __name__ == "__main__":
    main()
