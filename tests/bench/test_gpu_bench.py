"""`mpmfx bench gpu --quick` runs on the CPU and prints its table (speed itself is not tested)."""

from mpmfx.bench import gpu


def test_quick_gpu_bench_prints_table_and_writes_csv(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(gpu, "MATERIALS", ("Water", "Mushy"))  # keep it seconds: two materials
    assert gpu.main(quick=True, out=str(tmp_path)) == 0
    text = capsys.readouterr().out
    assert "G_per_s" in text and "Mixed" in text and "Mushy" in text
    rows = (tmp_path / "gpu.csv").read_text().splitlines()
    assert "error" not in rows[0]  # no case failed
    assert len(rows) == 1 + 2 * 2 + 4 + 10  # header, 2 materials x det off/on, mixed x det x path, 10 lever rows
