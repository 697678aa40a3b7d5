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
