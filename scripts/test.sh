#!/usr/bin/env bash
# Set up the environment, then run the tests. Extra arguments go to pytest, e.g.
#   bash scripts/test.sh -m "slow or not slow"     (everything, as CI does)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_env.sh"
cd "$root"
exec "$root/.venv/bin/python" -m pytest "$@"
