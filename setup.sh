#!/usr/bin/env bash
# mpmfx set-up, idempotent. Usage:
#   bash setup.sh            install only
#   bash setup.sh demo       install, then run the default shot end to end
#   bash setup.sh test       install, then lint (ruff) and run the test suite
# Installs Debian's python3-openvdb (apt), a virtual environment in .venv with numpy<2
# (Debian's pyopenvdb is built for numpy 1.x) and mpmfx editable with its test extras, which
# include Blender as a Python module (bpy 4.5 LTS, ~0.9 GB) for the Cycles renders.
set -euo pipefail
cd "$(dirname "$0")"
VENV=${MPMFX_VENV:-.venv}
PY_DEB=/usr/bin/python3.11
VDB_SO=/usr/lib/python3/dist-packages/pyopenvdb.cpython-311-x86_64-linux-gnu.so

say() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] error: %s\n' "$*" >&2; exit 1; }

apt_install() {
  local missing=()
  [[ -f $VDB_SO ]] || missing+=(python3-openvdb)
  command -v vdb_print >/dev/null || missing+=(libopenvdb-tools)
  $PY_DEB -c 'import ensurepip' 2>/dev/null || missing+=(python3-venv)
  [[ ${#missing[@]} -eq 0 ]] && return 0
  command -v apt-get >/dev/null || die "apt-get not found: install ${missing[*]} with your package manager (Debian 12 names), then run this again"
  local sudo=""
  [[ $(id -u) -eq 0 ]] || sudo="sudo"
  say "installing Debian packages: ${missing[*]}"
  { $sudo apt-get update -q && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q "${missing[@]}"; } >/tmp/mpmfx-apt.log 2>&1 \
    || die "apt-get install ${missing[*]} failed (log: /tmp/mpmfx-apt.log). As root run: apt-get update && apt-get install -y ${missing[*]}"
}

make_venv() {
  [[ -x $PY_DEB ]] || die "$PY_DEB not found: mpmfx needs Debian 12's python3.11 (apt-get install python3.11 python3-venv)"
  if [[ ! -x $VENV/bin/python ]]; then
    say "creating $VENV"
    $PY_DEB -m venv "$VENV"
  fi
  # The one place pyopenvdb becomes importable: a .pth naming a folder that holds only it,
  # so none of Debian's other Python packages (its numpy among them) leak into the venv.
  local site; site=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  mkdir -p "$VENV/debian-vdb"
  ln -sf "$VDB_SO" "$VENV/debian-vdb/"
  echo "$(cd "$VENV/debian-vdb" && pwd)" > "$site/mpmfx-debian-openvdb.pth"
  local stamp="$VENV/.mpmfx-installed"
  if [[ ! -f $stamp || pyproject.toml -nt $stamp ]]; then
    say "installing mpmfx and its dependencies into $VENV (first time: a few minutes)"
    "$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
    "$VENV/bin/python" -m pip install -q -e ".[test]" || die "pip install failed; see the messages above"
    touch "$stamp"
  fi
  "$VENV/bin/python" -c 'import pyopenvdb, numpy, warp' \
    || die "the environment in $VENV is broken; remove it (rm -rf $VENV) and run this again"
}

warm_kernels() {
  # the surfacer's CPU kernels, compiled once here rather than by the first run (seconds when cached)
  say "compiling the surfacer's CPU kernels (first time: about 2 minutes on 2 cores)"
  "$VENV/bin/python" -m mpmfx.stages.kernels || die "compiling Warp's kernels failed; see the messages above"
}

apt_install
make_venv
warm_kernels
case "${1:-}" in
  "") say "ready: $VENV/bin/mpmfx --help" ;;
  demo) shift; exec "$VENV/bin/mpmfx" run pipeline/shots/jelly_splash.toml "$@" ;;
  test)
    shift
    say "lint and format check (ruff)"
    "$VENV/bin/ruff" check . || die "ruff check found problems; '$VENV/bin/ruff check --fix .' fixes most"
    "$VENV/bin/ruff" format --check . || die "files need formatting: run '$VENV/bin/ruff format .'"
    exec "$VENV/bin/python" -m pytest "$@" ;;
  *) die "unknown command '$1': use 'demo', 'test' or nothing" ;;
esac
