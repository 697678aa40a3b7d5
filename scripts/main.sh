#!/usr/bin/env bash
# The main job: set up the environment, then render a .blend headless through the Blender
# add-on (bpy 5.0.1 module) to EXR + PNG, printing time and statistics.
#   bash scripts/main.sh [SCENE.blend] [render_blend.py options]
# SCENE defaults to blend_scenes/s_corridor.blend; the output is out/<scene name>.exr and .png
# (override the folder with ERCUTS_OUT). Further arguments go to blend_scenes/render_blend.py,
# e.g. bash scripts/main.sh blend_scenes/cornell_box.blend --integrator BDPT --time-limit 60
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
scene="$root/blend_scenes/s_corridor.blend"
if [ $# -gt 0 ] && [[ "$1" != -* ]]; then
  scene="$1"
  shift
  [[ "$scene" = /* ]] || scene="$PWD/$scene"
  [ -f "$scene" ] || { echo "main.sh: no such scene: $scene" >&2; exit 2; }
fi
bash "$root/scripts/setup_env.sh"
out="${ERCUTS_OUT:-$root/out}"
mkdir -p "$out"
cd "$root"
exec "$root/.venv/bin/python" blend_scenes/render_blend.py "$scene" \
  -o "$out/$(basename "$scene" .blend)" "$@"
