"""Bar chart of the surfacer's GPU kernel times before and after the tenth session's speed work
(10M random torus, "fine", one H200; `scripts/surface_profile.py --count 10000000 --shapes torus
--configs 0.5:8 --top 40` at the session's first and last runs, copied into
renders/readme/surface_gpu_kernels_h200_10m_torus_fine_s10.csv).

    python scripts/surface_gpu_chart.py   # -> renders/readme/surface_gpu_kernels_s10.png
"""
import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SRC = "renders/readme/surface_gpu_kernels_h200_10m_torus_fine_s10.csv"
OUT = "renders/readme/surface_gpu_kernels_s10.png"

rows = list(csv.DictReader(open(SRC)))
names = [r["kernel"] for r in rows][::-1]
before = [float(r["before_ms"]) for r in rows][::-1]
after = [float(r["after_ms"]) for r in rows][::-1]
fig, ax = plt.subplots(figsize=(8, 5.2), dpi=110)
y = range(len(names))
ax.barh([i + 0.2 for i in y], before, height=0.4, color="#b0b0b0", label="ninth session's code")
ax.barh([i - 0.2 for i in y], after, height=0.4, color="#2b7bb9", label="tenth session's code")
for i, (b, a) in enumerate(zip(before, after)):
    ax.text(max(a, b) + 0.8, i, f"{b:g} -> {a:g}", va="center", fontsize=8)
ax.set_yticks(list(y), names, fontsize=8)
ax.set_xlabel("ms (10M particles, random torus, \"fine\", one H200)")
ax.set_xlim(0, max(before) * 1.22)
ax.legend(loc="lower right", fontsize=8)
ax.set_title("Surfacer on the GPU: where a call's time goes", fontsize=10)
fig.tight_layout()
fig.savefig(OUT)
print(OUT)
