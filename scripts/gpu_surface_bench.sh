#!/usr/bin/env bash
# Surfacer speed/accuracy on the GPU: sparse (default) at 1M and 10M, dense at 1M for comparison.
# Usage on the GPU machine (warp under /opt/wp/site, see ../shared/gpu/prepare-warp.sh):
#   bash scripts/gpu_surface_bench.sh        (about 2-4 minutes on one H200)
# Columns: see mpmfx/surface/bench.py. Sparse rows at >= 2M particles return only the sparse
# level set (SurfaceParams.dense_output=False); the "stages" lines are cumulative seconds.
set -uo pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=/opt/wp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
t0=$(date +%s)
{
  timeout 200 python3 -m mpmfx.surface.bench --counts 1000000 10000000 --device cuda --stages
  timeout 60 python3 -m mpmfx.surface.bench --counts 1000000 --shapes sphere --grids DENSE --device cuda | tail -n +2
} 2>&1 | grep -v '^Module\|^Warp\|^   '
echo "took $(( $(date +%s) - t0 )) s"
