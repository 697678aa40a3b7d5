"""The package layout the README promises: no import cycle in ``ercuts_core`` or ``addon``
(``scripts/import_cycles.py``), the paper's steps together in one package, no bpy in the core."""
from __future__ import annotations

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import import_cycles  # noqa: E402

STEPS = ("initialization", "seeding", "er_sampling", "mutations", "paths", "vpl", "light_tree", "progressive",
         "lightcuts", "gather", "pacing", "integrator")


def test_no_import_cycles_in_core_and_addon():
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "import_cycles.py"),
                           "ercuts_core", "addon"], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.strip().endswith(" 0 cycles")


def test_checker_finds_a_cycle_even_through_a_lazy_import(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..a import x\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import a\n")
    graph = import_cycles.import_graph([str(pkg)])
    assert graph["pkg.a"] == {"pkg.sub.b"} and graph["pkg.sub.b"] == {"pkg.a"}
    assert graph["pkg.c"] == set()                      # TYPE_CHECKING imports do not count
    assert import_cycles.cycles(graph) == [["pkg.a", "pkg.sub.b"]]
    assert import_cycles.main([str(pkg)]) == 1


def test_the_papers_steps_live_in_one_package():
    graph = import_cycles.import_graph([os.path.join(ROOT, "ercuts_core")])
    for step in STEPS:
        assert f"ercuts_core.integrators.ercuts.{step}" in graph, step
        assert not os.path.exists(os.path.join(ROOT, "ercuts_core", f"{step}.py")), step
    # BDPT knows nothing of the Ercuts package: the seeds come through its callback
    assert not any(m.startswith("ercuts_core.integrators.ercuts")
                   for m in graph["ercuts_core.integrators.bdpt"])


def test_core_never_imports_bpy():
    for path in import_cycles.modules(os.path.join(ROOT, "ercuts_core")).values():
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        assert "import bpy" not in text and "from bpy" not in text, path
