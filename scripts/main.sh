#!/usr/bin/env bash
# The main job: set up the environment, then render the default scene headless to EXR + PNG,
# printing time and statistics. Output goes to out/ (override with ERCUTS_OUT).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_env.sh"
out="${ERCUTS_OUT:-$root/out}"
mkdir -p "$out"
cd "$root"
exec "$root/.venv/bin/python" -m ercuts_core render builtin:s_corridor \
  -o "$out/s_corridor.exr" --png "$out/s_corridor.png" --stats "$out/s_corridor.json" "$@"
