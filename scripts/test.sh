#!/usr/bin/env bash
# Set up the environment, then run the tests:
#   1. the whole suite with pytest in .venv (the core, and the add-on under the bpy 5.0.1 module);
#   2. the add-on suite again inside Debian's Blender 3.4.1 (`blender -b`), installed with apt
#      when missing and possible (root on Debian); set ERCUTS_SKIP_BLENDER34=1 to skip it.
# Extra arguments go to both pytest runs, e.g.
#   bash scripts/test.sh -m "slow or not slow"     (everything, as CI does)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_env.sh"
cd "$root"
status=0
# blender first: step 1's tests/test_cli_batch.py runs the binary too.
# xvfb-run and Mesa's software OpenGL let tests/test_viewport_gui.py open a Blender window.
if [ "${ERCUTS_SKIP_BLENDER34:-0}" != 1 ] && { ! command -v blender >/dev/null 2>&1 \
    || ! command -v xvfb-run >/dev/null 2>&1; } \
    && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "test.sh: installing Debian's blender, xvfb and Mesa for the Blender 3.4 add-on tests"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      blender xvfb libgl1-mesa-dri >/dev/null) \
    || echo "test.sh: could not install blender/xvfb"
fi
"$root/.venv/bin/python" -m pytest "$@" || status=$?
if [ "${ERCUTS_SKIP_BLENDER34:-0}" != 1 ]; then
  if command -v blender >/dev/null 2>&1; then
    echo "test.sh: add-on tests inside $(blender --version 2>/dev/null | head -n 1)"
    PYTHONPATH="$root/.venv/lib/python3.11/site-packages:$root" \
      blender -b --factory-startup --python-exit-code 1 \
      --python tests/blender/run_in_blender.py -- -p no:cacheprovider "$@" tests/blender || status=$?
  else
    echo "test.sh: no blender binary; Blender 3.4 add-on tests not run"
  fi
fi
exit $status
