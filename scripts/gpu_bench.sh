#!/usr/bin/env bash
# The GPU session's benchmark runs, one table each (see README "Benchmarks").
# Usage on the GPU machine (after ../shared/gpu/prepare-warp.sh's two stages):
#   bash scripts/gpu_bench.sh solver|pipeline|shots|surface|accuracy ...   results under ${OUT:-renders/bench}
set -uo pipefail
export PYTHONUNBUFFERED=1 PYTHONPATH=/opt/wp/site:$PWD${PYTHONPATH:+:$PYTHONPATH}
out=${OUT:-renders/bench}
mkdir -p "$out"
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
for what in "$@"; do
  echo "=== $what"
  t0=$(date +%s)
  case $what in
    solver|surface|accuracy) timeout 280 python3 -m mpmfx.cli bench "$what" --device cuda --out "$out" 2>&1 | grep -v '^Module' ;;
    pipeline) MPMFX_CACHE=/tmp/mpmfx-cache timeout 280 python3 -m mpmfx.cli run pipeline/shots/jelly_splash.toml \
                --until surface --device cuda -q 2>&1 | grep -v '^Module' ;;
    shots) for shot in ${SHOTS:-pipeline/shots/*.toml}; do  # every example, twice: the second run has warm kernels
             echo "--- $shot"; rm -rf /tmp/mpmfx-shots
             for i in 1 2; do MPMFX_CACHE=/tmp/mpmfx-shots timeout 120 python3 -m mpmfx.cli run "$shot" --until surface \
                 --device cuda -q --force voxelise --force simulate --force surface 2>&1 | grep -v '^Module' | tail -4; done
           done ;;
  esac
  echo "=== $what took $(( $(date +%s) - t0 )) s"
done
