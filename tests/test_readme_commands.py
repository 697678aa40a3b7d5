"""Every documented command works verbatim and fails loudly (issue 18).

:func:`extract` takes every command of every fenced ``bash`` (or ``sh``/``shell``) block of
:data:`READMES`, in order; nothing here lists commands. ``test_readme_command`` (slow) runs
each exactly as written with ``bash -e -o pipefail -c``, one after another in one copy of the
repository (:mod:`repo_copy`), and fails on a non-zero exit status. The environment is the
only thing the test chooses:

* ``ERCUTS_QUICK=1``, which the READMEs document: every Ercuts render stops after 3 s,
  ``benchmarks/report.py`` and ``make_references.py`` make a small run under ``out/quick/``;
* temporary Blender user folders (``BLENDER_USER_*``), no ``PYTHONPATH``, no ``ERCUTS_OUT``;
* ``blender`` on ``PATH`` is the real binary, except that ``blender --command …`` (Blender
  ≥ 4.2; Debian's is 3.4) runs the same command through bpy 5.0.1 (:data:`SHIM`);
* ``build/wheels``, ``scripts/build_addon.py``'s download cache, is the checkout's (when it
  exists), so the wheels are downloaded once.

A command is skipped only when its own text gives the reason ("not run by the README test:
…", visible in the README) or when the machine has no ``blender`` for a Blender line. The
fast tests check the extractor, the rules every command has to follow to fail loudly, and
that the runner does fail on a broken command (a wrong zip path).
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import time
from dataclasses import dataclass

import pytest

import repo_copy

ROOT = repo_copy.ROOT
READMES = ("README.md", "blend_scenes/README.md", "benchmarks/README.md")
SHELL_INFO = {"bash", "sh", "shell"}
#: A command that cannot run here says so, visibly, in its own comment.
SKIP_MARK = re.compile(r"not run by the README test:\s*(.+)$", re.MULTILINE)
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([^\s`]*)")
#: ``blender`` in command position (start, after ``;``, ``&&``, ``|``, ``(``, or after
#: ``VAR=value`` prefixes) — the lines that need a Blender binary.
BLENDER_CMD = re.compile(r"(?:^|[;&|(]\s*|\n\s*)(?:[A-Za-z_][A-Za-z0-9_]*=\S*\s+(?:\\\n\s*)?)*blender\s")
TIMEOUT = 900


@dataclass(frozen=True)
class Command:
    readme: str
    line: int  # 1-based line of the command's first line in the README
    text: str  # exactly as written (continuation lines included)

    @property
    def skip_reason(self) -> str | None:
        m = SKIP_MARK.search(self.text)
        return m.group(1).strip() if m else None

    @property
    def id(self) -> str:
        """``README:line first words`` (without the comment), for -k."""
        words = re.sub(r"\s+", " ", self.text.replace("\\\n", " ").split(" #")[0]).strip()
        return f"{self.readme}:{self.line} {words[:50]}"


def _complete(text: str) -> bool:
    """True when ``text`` is a complete bash command (``bash -n`` accepts it)."""
    return subprocess.run(["bash", "-n", "-c", text], capture_output=True).returncode == 0


def extract(markdown: str, name: str = "<text>") -> list[Command]:
    """The commands of the shell blocks of ``markdown``: lines joined while they end with a
    backslash or do not yet form a complete bash command (loops, quotes, here-documents);
    blank lines and whole-line comments between commands are dropped."""
    commands: list[Command] = []
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, info = m.group(1), m.group(2), m.group(3).lower()
        body_start = i + 1
        j = body_start
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        if info in SHELL_INFO:
            buf: list[str] = []
            first = 0
            for k in range(body_start, j):
                line = lines[k][len(indent):] if lines[k].startswith(indent) else lines[k].lstrip()
                if not buf and (not line.strip() or line.lstrip().startswith("#")):
                    continue
                if not buf:
                    first = k + 1
                buf.append(line)
                if line.endswith("\\"):
                    continue
                text = "\n".join(buf)
                if _complete(text):
                    commands.append(Command(name, first, text))
                    buf = []
            if buf:
                raise ValueError(f"{name}:{first}: incomplete shell command: {' '.join(buf)!r}")
        i = j + 1
    return commands


def readme_commands() -> list[Command]:
    found = []
    for rel in READMES:
        with open(os.path.join(ROOT, rel), encoding="utf-8") as fh:
            found += extract(fh.read(), rel)
    return found


COMMANDS = readme_commands()


def _blender_version(binary: str) -> tuple[int, ...]:
    out = subprocess.run([binary, "--version"], capture_output=True, text=True, timeout=120).stdout
    m = re.search(r"Blender (\d+)\.(\d+)", out)
    return (int(m.group(1)), int(m.group(2))) if m else (0, 0)


#: ``blender --command NAME ARGS`` through bpy 5.0.1: the handler Blender ≥ 4.2 registers for
#: NAME (``extension``: bl_pkg's), called with the same arguments; its status is the exit status.
SHIM = '''import sys
import bpy  # noqa: F401  (first: it sets up Blender's module paths)
name, args = sys.argv[1], sys.argv[2:]
if name != "extension":
    sys.exit(f"README test: no bpy equivalent of 'blender --command {name}'")
import bl_pkg
sys.exit(bl_pkg.cli_extension(args))
'''


def _blender_wrapper(folder: str, real: str | None, venv: str) -> None:
    """``folder/blender``: the real binary, with ``--command`` (Blender ≥ 4.2) through bpy."""
    shim = os.path.join(folder, "blender_command.py")
    with open(shim, "w") as fh:
        fh.write(SHIM)
    python = shlex.quote(os.path.join(venv, "bin", "python"))
    fallback = f'exec {shlex.quote(real)} "$@"' if real else 'echo "no blender binary" >&2; exit 127'
    wrapper = os.path.join(folder, "blender")
    with open(wrapper, "w") as fh:
        fh.write("#!/usr/bin/env bash\n"
                 "# README test: Debian's Blender is 3.4, 'blender --command' needs 4.2: use bpy 5.0.1.\n"
                 f'if [ "${{1:-}}" = --command ]; then exec {python} {shlex.quote(shim)} "${{@:2}}"; fi\n'
                 f"{fallback}\n")
    os.chmod(wrapper, 0o755)


def command_env(base: str) -> dict:
    """The environment of a documented command: the user's, minus what would change the
    commands' meaning, with ``ERCUTS_QUICK=1`` and Blender's user folders under ``base``."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "ERCUTS_OUT", "VIRTUAL_ENV", "PYTHONHOME")
           and not k.startswith("BLENDER_USER_")}
    user = os.path.join(base, "blender_user")
    env.update(ERCUTS_QUICK="1", BLENDER_USER_RESOURCES=user,
               BLENDER_USER_CONFIG=os.path.join(user, "config"),
               BLENDER_USER_SCRIPTS=os.path.join(user, "scripts"),
               BLENDER_USER_DATAFILES=os.path.join(user, "datafiles"),
               BLENDER_USER_EXTENSIONS=os.path.join(user, "extensions"))
    return env


def run_command(command: Command | str, cwd: str, env: dict,
                timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """Run one documented command verbatim (``bash -e -o pipefail -c``)."""
    text = command.text if isinstance(command, Command) else command
    return subprocess.run(["bash", "-e", "-o", "pipefail", "-c", text], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def check(command: Command | str, proc: subprocess.CompletedProcess) -> None:
    """Fail, with the end of its output, unless the command exited 0."""
    text = command.text if isinstance(command, Command) else command
    assert proc.returncode == 0, (
        f"exit status {proc.returncode} of\n{text}\n--- stdout (end) ---\n{proc.stdout[-3000:]}"
        f"\n--- stderr (end) ---\n{proc.stderr[-3000:]}")


# --------------------------------------------------------------------------- the commands

@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """(repository copy, environment) shared by the commands, which build on each other."""
    base = str(tmp_path_factory.mktemp("readme"))
    repo = repo_copy.make_copy(os.path.join(base, "repo"))
    cache = os.path.join(ROOT, "build", "wheels")  # build_addon.py's download cache, if any
    if os.path.isdir(cache):
        os.makedirs(os.path.join(repo, "build"))
        os.symlink(cache, os.path.join(repo, "build", "wheels"))
    env = command_env(base)
    real = shutil.which("blender")
    if real is None or _blender_version(real) < (4, 2):
        wrappers = os.path.join(base, "bin")
        os.makedirs(wrappers)
        _blender_wrapper(wrappers, real, os.path.join(repo, ".venv"))
        env["PATH"] = wrappers + os.pathsep + env.get("PATH", "")
    return repo, env


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS, ids=[c.id for c in COMMANDS])
def test_readme_command(command, workspace):
    if command.skip_reason:
        pytest.skip(command.skip_reason)
    needs_blender = BLENDER_CMD.search(command.text) and "--command" not in command.text
    if needs_blender and shutil.which("blender") is None:
        pytest.skip("no blender binary (CI installs Debian's)")
    repo, env = workspace
    t0 = time.monotonic()
    proc = run_command(command, repo, env)
    print(f"{command.id}: exit {proc.returncode} in {time.monotonic() - t0:.1f} s")
    check(command, proc)


# --------------------------------------------------------------------------- fast checks

def test_every_readme_has_commands():
    for rel in READMES:
        assert [c for c in COMMANDS if c.readme == rel], f"no bash block found in {rel}"


def test_extractor():
    md = "\n".join([
        "text", "```bash", "# a comment", "echo one   # trailing", "", "echo two \\",
        "  --flag", "for i in 1 2; do", "  echo $i", "done", "echo 'a", "b'", "```",
        "```python", "print('not shell')", "```",
        "- item", "  ```sh", "  echo three  # not run by the README test: because", "  ```",
        "```", "echo untagged", "```",
    ])
    cmds = extract(md, "x.md")
    assert [c.text for c in cmds] == ["echo one   # trailing", "echo two \\\n  --flag",
                                      "for i in 1 2; do\n  echo $i\ndone", "echo 'a\nb'",
                                      "echo three  # not run by the README test: because"]
    assert [c.line for c in cmds] == [4, 6, 8, 11, 19]
    assert [c.skip_reason for c in cmds] == [None] * 4 + ["because"]
    with pytest.raises(ValueError, match="incomplete"):
        extract("```bash\necho 'open\n```\n")


def test_blender_detection():
    hits = ["blender -b x", "PYTHONPATH=a:. blender -b", "PYTHONPATH=a:. \\\n  blender -b",
            "cd x && blender -b", "nice -n 19 .venv/bin/python a.py; blender -b"]
    misses = [".venv/bin/python blend_scenes/build_scenes.py", "echo blender_helpers"]
    assert all(BLENDER_CMD.search(t) for t in hits)
    assert not any(BLENDER_CMD.search(t) for t in misses)


def test_skips_are_explained():
    """The only skips: those the README explains, and scripts/test.sh is one of them (it
    runs this test)."""
    for c in COMMANDS:
        if re.search(r"scripts/test\.sh", c.text):
            assert c.skip_reason, f"{c.id}: would run the tests recursively"


def test_blender_python_lines_set_an_exit_code():
    """Blender exits 0 when a ``--python``/``--python-expr`` script raises, unless
    ``--python-exit-code`` is given: every documented Blender line with a script has it."""
    for c in COMMANDS:
        if BLENDER_CMD.search(c.text) and re.search(r"--python(-expr)?\s", c.text):
            assert "--python-exit-code" in c.text, f"{c.id}: no --python-exit-code"


def test_core_renders_state_their_time():
    """A newcomer's first core render says how long it takes: ``--time-limit``."""
    renders = [c for c in COMMANDS if re.search(r"-m ercuts_core render\b", c.text)]
    assert renders
    for c in renders:
        assert "--time-limit" in c.text, f"{c.id}: no --time-limit"


def test_paths_in_commands_are_the_build_outputs():
    """Every zip a command names is where scripts/build_addon.py writes it (dist/)."""
    for c in COMMANDS:
        for zip_path in re.findall(r"[\w./-]*ercuts-[\w.-]+\.zip", c.text):
            assert zip_path.startswith("dist/"), f"{c.id}: {zip_path} is not in dist/"


BLENDER = shutil.which("blender")


def _install_line() -> Command:
    (line,) = [c for c in COMMANDS if "addon_install" in c.text]
    return line


@pytest.mark.skipif(BLENDER is None, reason="no blender binary (CI installs Debian's)")
def test_runner_fails_on_a_broken_command(tmp_path):
    """The README's 3.x install line with a wrong zip path exits non-zero, and the runner
    reports it; the same line without ``--python-exit-code`` would have exited 0."""
    line = _install_line()
    assert "dist/ercuts-0.1.0-legacy.zip" in line.text
    env = command_env(str(tmp_path))
    broken = line.text.replace("dist/ercuts-0.1.0-legacy.zip", "dist/no-such-addon.zip")
    proc = run_command(broken, str(tmp_path), env, timeout=300)
    assert proc.returncode != 0
    assert "no-such-addon.zip" in proc.stdout + proc.stderr
    with pytest.raises(AssertionError, match="exit status"):
        check(broken, proc)
    without_flag = broken.replace("--python-exit-code 1 ", "")
    assert without_flag != broken
    assert run_command(without_flag, str(tmp_path), env, timeout=300).returncode == 0

