#!/usr/bin/env bash
# The main job: set up the environment, then render the S-corridor .blend headless through the
# Blender add-on (bpy 5.0.1 module) to EXR + PNG, printing time and statistics. Output goes to
# out/ (override with ERCUTS_OUT); extra arguments go to blend_scenes/render_blend.py
# (e.g. --integrator BDPT --time-limit 60).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_env.sh"
out="${ERCUTS_OUT:-$root/out}"
mkdir -p "$out"
cd "$root"
exec "$root/.venv/bin/python" blend_scenes/render_blend.py blend_scenes/s_corridor.blend \
  -o "$out/s_corridor" "$@"
