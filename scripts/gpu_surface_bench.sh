#!/usr/bin/env bash
# Surfacer speed/accuracy on the GPU: sparse (default) at 1M and 10M, then for comparison
# sparse with dense output arrays and the old dense path, at 1M (sphere).
# Usage on the GPU machine (warp under /opt/wp/site, see ../shared/gpu/prepare-warp.sh):
#   bash scripts/gpu_surface_bench.sh        (expected 2-4 minutes on one H200)
# Columns: see mpmfx/surface/bench.py; "grid" is the number of 8^3 blocks kept in the sparse
# output. "stages" lines are cumulative seconds after each stage of the sparse path.
set -uo pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=/opt/wp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
t0=$(date +%s)
{
  timeout 220 python3 -m mpmfx.surface.bench --counts 1000000 10000000 --device cuda --stages
  timeout 35 python3 -m mpmfx.surface.bench --counts 1000000 --shapes sphere --samplings random --device cuda \
    --dense-output | tail -n +2
  timeout 35 python3 -m mpmfx.surface.bench --counts 1000000 --shapes sphere --grids DENSE --device cuda | tail -n +2
} 2>&1 | grep -v '^Module\|^Warp\|^   '
echo "took $(( $(date +%s) - t0 )) s"
