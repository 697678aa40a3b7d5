"""Run the add-on tests inside a real Blender binary (e.g. Debian's Blender 3.4.1).

    PYTHONPATH=.venv/lib/python3.11/site-packages:. \
        blender -b --factory-startup --python-exit-code 1 \
        --python tests/blender/run_in_blender.py -- -q tests/blender

Arguments after ``--`` go to pytest; its exit status becomes Blender's.
"""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else ["-q", os.path.join(ROOT, "tests", "blender")]
os.chdir(ROOT)
sys.exit(pytest.main(argv))
