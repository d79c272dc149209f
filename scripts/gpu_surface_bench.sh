#!/usr/bin/env bash
# `mpmfx bench surface` on the GPU machine: ours (fast, fine) and every installed peer
# (splashsurf on the CPU cores, Newton isotropic / anisotropic on the GPU) on the same particles.
# Usage there (warp, newton, pysplashsurf under /opt/wp/site, see ../shared/gpu/prepare-warp.sh
# with EXTRA="newton==1.8.0 pysplashsurf==0.14.1.0"):
#   bash scripts/gpu_surface_bench.sh OUT_DIR [COUNT ...]      (default counts: 1M 10M)
# 1M takes about a minute on one H100, 10M about five (splashsurf dominates).
set -uo pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=/opt/wp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
out=${1:?usage: gpu_surface_bench.sh OUT_DIR [COUNT ...]}
shift
counts=("${@:-1000000 10000000}")
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
nproc
t0=$(date +%s)
python3 -m mpmfx.cli bench surface --device cuda --counts ${counts[@]} --out "$out" 2>&1 | grep -v '^Module\|^Warp\|^   '
echo "took $(( $(date +%s) - t0 )) s"
