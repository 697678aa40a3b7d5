"""Settings reject unknown keys and bad values; ercuts_core never imports bpy."""
from __future__ import annotations

import ast
import pathlib
import subprocess
import sys

import pytest

from ercuts_core import RenderSettings

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_from_dict_rejects_unknown_keys():
    with pytest.raises(ValueError, match="unknown render settings: smaples"):
        RenderSettings.from_dict({"smaples": 4})


def test_from_dict_round_trip():
    s = RenderSettings(integrator="PATH", samples=3, seed=7)
    assert RenderSettings.from_dict(s.to_dict()) == s


@pytest.mark.parametrize("bad", [{"samples": 0}, {"rough_samples": 0}, {"integrator": "FOO"}, {"max_depth": 0},
                                 {"time_limit": -1.0}, {"memory_budget_mb": -1}])
def test_bad_values_raise(bad):
    with pytest.raises(ValueError):
        RenderSettings(**bad)


def test_core_never_imports_bpy():
    for path in (ROOT / "ercuts_core").rglob("*.py"):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            assert not any(n == "bpy" or n.startswith("bpy.") for n in names), path


def test_core_imports_in_a_plain_interpreter():
    code = "import sys, ercuts_core; assert 'bpy' not in sys.modules; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


@pytest.mark.parametrize("address", ["", "local", "auto", "ray://head.example:10001", "10.0.0.5:6379"])
def test_cluster_addresses(address):
    assert RenderSettings(cluster=address).cluster == address


@pytest.mark.parametrize("address", ["ray://", "head", "http://head:1", "local "])
def test_bad_cluster_addresses_raise(address):
    with pytest.raises(ValueError, match="cluster must be"):
        RenderSettings(cluster=address)
