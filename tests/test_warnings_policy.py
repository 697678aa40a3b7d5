"""The test run fails on warnings from the project's own code (pyproject.toml's
``filterwarnings``): numpy's RuntimeWarnings (divide by zero, invalid value, overflow)
used to pass by, 20 of them in tests/test_fuzz.py. Other libraries' warnings, such as
their DeprecationWarnings, are only shown."""
from __future__ import annotations

import warnings

import numpy as np
import pytest


def _run_as(module: str, code: str) -> None:
    """Run ``code`` as if it were a line of ``module`` (warnings name that module)."""
    exec(compile(code, f"<{module}>", "exec"), {"__name__": module, "np": np, "warnings": warnings})


@pytest.mark.parametrize("module", ["ercuts_core.lights", "ercuts_core", "addon.engine"])
def test_numpy_warnings_in_project_code_are_errors(module):
    with pytest.raises(RuntimeWarning, match="divide by zero"):
        _run_as(module, "np.array([1.0]) / np.array([0.0])")


def test_third_party_deprecations_only_show():
    with pytest.warns(DeprecationWarning):
        _run_as("somelibrary.module", "warnings.warn('old API', DeprecationWarning)")
