"""``python -m ercuts_core --help`` (and each subcommand's) is plain text: the module
docstring used to reach the terminal with its reStructuredText markup (````.npz````,
``Examples::``)."""
from __future__ import annotations

import re

import pytest

from ercuts_core.__main__ import main

#: reStructuredText that must not reach a terminal: inline literals, literal-block markers,
#: roles such as :mod:`x`.
RST = re.compile(r"``|::\s*$|:[a-z]+:`", re.MULTILINE)


@pytest.mark.parametrize("command", [[], ["render"], ["save-builtin"]])
def test_help_is_plain_text(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: python -m ercuts_core")
    assert not RST.findall(text), text
    assert len(text.splitlines()) > 8          # there is help beyond the usage line


def test_render_help_lists_integrators_and_scenes(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = capsys.readouterr().out
    assert "{ERCUTS,BDPT,PATH}" in text and "cornell_box" in text


def test_render_log_is_not_flooded(tmp_path):
    """With stderr going to a log, the progress bar redraws at most every
    BAR_INTERVAL_LOG seconds (it used to redraw on every progress call: hundreds of chunks
    for a few seconds of rendering)."""
    import os
    import subprocess
    import sys
    import time

    from ercuts_core.__main__ import BAR_INTERVAL_LOG

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "ercuts_core", "render", "builtin:cornell_box", "-o",
                           str(tmp_path / "c.exr"), "--width", "48", "--height", "36", "--time-limit", "6"],
                          cwd=root, capture_output=True, text=True, timeout=300,
                          env={k: v for k, v in os.environ.items() if k != "ERCUTS_QUICK"})
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr
    redraws = proc.stderr.count("\n")        # tqdm writes a line per redraw into a log
    assert redraws <= elapsed / BAR_INTERVAL_LOG + 3, (redraws, elapsed, proc.stderr[-2000:])
