#!/usr/bin/env bash
# Create or refresh the project's virtual environment (.venv) from requirements.txt.
# Needs Python 3.11 (bpy 5.0.1 supports nothing else). On Debian 12 as root it installs
# python3-venv when missing. Re-running is cheap: pip is skipped while requirements.txt
# is unchanged.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
py="${ERCUTS_PYTHON:-}"
if [ -z "$py" ]; then
  for cand in python3.11 /usr/bin/python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      py="$cand"; break
    fi
  done
fi
[ -n "$py" ] || { echo "setup: Python 3.11 is required (bpy 5.0.1 needs it)" >&2; exit 1; }
if [ ! -x "$venv/bin/python" ]; then
  if ! "$py" -m venv "$venv" 2>/dev/null; then
    rm -rf "$venv"
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      apt-get update -qq && apt-get install -y -qq python3-venv python3.11-venv >/dev/null
      "$py" -m venv "$venv"
    else
      echo "setup: '$py -m venv' failed; install python3-venv" >&2; exit 1
    fi
  fi
fi
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$root/requirements.txt" | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  n="$(grep -cE '^[[:space:]]*[^#[:space:]]' "$root/requirements.txt")"
  echo "setup: installing requirements.txt ($n packages) into .venv" \
       "(first run ≈ 1 min, 1.3 GB, most of it bpy)…"
  "$venv/bin/python" -m pip install -q --upgrade pip
  "$venv/bin/python" -m pip install --progress-bar on -r "$root/requirements.txt"
  echo "setup: .venv ready"
  echo "$want" > "$stamp"
fi
