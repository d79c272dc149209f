"""`mpmfx bench voxelise`: the rows it reports are real voxelisations."""

import json
import math

from mpmfx.cli import main


def test_quick_voxelise_bench_reports_a_sphere_of_the_right_size(tmp_path):
    assert main(["bench", "voxelise", "--quick", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "voxelise.json").read_text())
    expected = 4 / 3 * math.pi * 0.3**3 * 64**3 * 8  # sphere volume in cells x 8 particles per cell
    assert [row["mesh"] for row in rows] == ["closed", "open"]
    for row in rows:  # the holes do not let the fill leak
        assert abs(row["particles"] / expected - 1) < 0.03
        assert row["verdict"] == "PASS" and row["voxelise_s"] > 0
