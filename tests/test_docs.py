"""Every shell and Python block of README.md and docs/*.md runs, as a user would run it.

Blocks of one file run in order, in one fresh folder, Python blocks sharing a
namespace. In a ``console`` block, lines starting with ``$ `` are commands and
the lines after them the output they must print: every documented output line
must appear in what the command printed, so the docs cannot drift from the
code. A block preceded by ``<!-- docs-test: skip REASON -->`` is not run (the
reason must say why: hardware, measured data not shipped, or a command that
would run this test suite itself).

A console line that is a plain ``piezohyst`` command (no pipe, redirection,
variable or second command) runs in this process, through the CLI's own entry
point (``click``'s runner, warnings shown as a user's process shows them): the
same code path without starting Python and loading the compiled kernels again
for each of the ~40 documented commands. So does a ``sh`` block made only of such
commands and ``python -c "..."`` scripts (each script in a fresh namespace). Every
other line runs in ``bash``; the installed console script itself is run as a
subprocess in tests/cli.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner

from piezohyst.cli import main as cli_main

ROOT = Path(__file__).resolve().parent.parent
FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\s*$")
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s+(.+?)\s*-->")
#: A block that builds C (``export-c --shared``) runs where a C compiler is, else is skipped
NEEDS_CC = re.compile(r"<!--\s*docs-test:\s*needs a C compiler\s*-->")
HAS_CC = any(shutil.which(name) for name in ("cc", "gcc", "clang"))
RUNNABLE = {"python", "sh", "bash", "console"}
#: what makes a console line need a shell
SHELL_SYNTAX = re.compile(r"[|&;<>$`*?(){}\[\]~]")


@dataclass(frozen=True)
class Block:
    lang: str
    text: str
    line: int
    skip: str | None


def blocks(path: Path) -> list[Block]:
    out = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m and m.group(1):
            start = i
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            prev = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
            skip = SKIP.search(prev)
            reason = skip.group(1) if skip else None
            if NEEDS_CC.search(prev) and not HAS_CC:
                reason = "builds C, and this machine has no C compiler"
            out.append(Block(m.group(1), "\n".join(lines[start + 1 : j]), start + 1, reason))
            i = j + 1
        else:
            i += 1
    return out


def _env(tmp: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    env.pop("CI", None)
    return env


def _in_process(command: str) -> tuple[int, str] | None:
    """Exit status and output of a plain ``piezohyst`` command run in this process (None:
    the line needs a shell)."""
    if SHELL_SYNTAX.search(command):
        return None
    args = shlex.split(command)
    if not args or args[0] != "piezohyst":
        return None
    return _cli(args)


def _cli(args: list[str]) -> tuple[int, str]:
    """Exit status and output of ``piezohyst ARGS`` run through the CLI's entry point."""
    with warnings.catch_warnings():
        warnings.resetwarnings()  # as a user's process: the suite's warnings-as-errors off
        res = CliRunner().invoke(cli_main, args[1:], prog_name="piezohyst")
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return res.exit_code, res.output


def _run_console(block: Block, cwd: Path, where: str) -> None:
    commands: list[tuple[str, list[str]]] = []
    for line in block.text.splitlines():
        if line.startswith("$ "):
            commands.append((line[2:], []))
        elif commands:
            commands[-1][1].append(line)
    last_status = 0
    for command, expected in commands:
        if command.strip() == "echo $?":
            got = f"{last_status}"
        else:
            ran = _in_process(command)
            if ran is None:
                res = subprocess.run(
                    ["bash", "-c", command], cwd=cwd, env=_env(cwd), capture_output=True, text=True
                )
                ran = (res.returncode, res.stdout + res.stderr)
            last_status, got = ran
            if not any(e.startswith("error:") for e in expected):
                assert last_status == 0, f"{where}: `{command}` failed:\n{got}"
        for line in expected:
            if line.strip():
                assert line.strip() in got, f"{where}: `{command}` did not print {line!r}:\n{got}"


def _commands(text: str) -> list[list[str]] | None:
    """A shell block's commands as argument lists (continuations joined, quoted strings over
    several lines kept whole, comments dropped), or None where a line is anything but a
    plain ``piezohyst`` command or ``python -c "..."``: then the block runs in ``bash``."""
    out: list[list[str]] = []
    current = ""
    for line in text.splitlines():
        current = f"{current}\n{line}" if current else line
        if current.endswith("\\"):
            continue  # a continuation line follows
        joined = current.replace("\\\n", "")  # bash removes a backslash-newline
        try:
            args = shlex.split(joined, comments=True)
        except ValueError:
            continue  # a quoted string goes on over the next line
        current = ""
        if not args:
            continue
        python_c = (
            len(args) == 3
            and args[:2] == ["python", "-c"]
            and joined.rstrip().endswith('"')
            and not re.search(r"[$`\\]", joined)  # nothing bash would expand in the quotes
        )
        plain = args[0] == "piezohyst" and not SHELL_SYNTAX.search(shlex.join(args))
        if not (python_c or plain):
            return None
        out.append(args)
    return None if current.strip() else out


def _run_shell(block: Block, cwd: Path, where: str) -> None:
    """A block of plain ``piezohyst`` commands and ``python -c`` scripts runs in this process
    (each script in a fresh namespace, warnings shown as a user's process shows them: the
    docs' walkthroughs start some thirty such processes, each loading Python, NumPy and the
    compiled kernels again); any other block runs in ``bash -euo pipefail``."""
    commands = _commands(block.text)
    if commands is not None:
        for args in commands:
            if args[0] == "python":
                with warnings.catch_warnings():
                    warnings.resetwarnings()
                    exec(compile(args[2], where, "exec"), {"__name__": "__main__"})
                continue
            status, got = _cli(args)
            assert status == 0, f"{where}: `{shlex.join(args)}` failed:\n{got}"
        return
    res = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", block.text],
        cwd=cwd,
        env=_env(cwd),
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, f"{where} failed:\n{res.stdout}{res.stderr}"


@pytest.mark.parametrize("path", FILES, ids=[p.name for p in FILES])
def test_every_block_runs(path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {"__name__": "__docs__"}
    ran = 0
    for block in blocks(path):
        if block.lang not in RUNNABLE:
            continue
        where = f"{path.name}:{block.line}"
        if block.skip:
            assert len(block.skip) > 8, f"{where}: say why the block is skipped"
            continue
        if block.lang == "python":
            exec(compile(block.text, where, "exec"), namespace)
        elif block.lang == "console":
            _run_console(block, tmp_path, where)
        else:
            _run_shell(block, tmp_path, where)
        ran += 1
    runnable = [b for b in blocks(path) if b.lang in RUNNABLE]
    assert ran == len([b for b in runnable if not b.skip])


def test_the_parser_sees_blocks_and_skips(tmp_path: Path) -> None:
    text = (
        "intro\n<!-- docs-test: skip needs a DAQ card -->\n```python\nx = 1\n```\n```sh\nls\n```\n"
    )
    path = tmp_path / "probe.md"
    path.write_text(text)
    found = blocks(path)
    assert [(b.lang, b.skip) for b in found] == [("python", "needs a DAQ card"), ("sh", None)]


def test_a_shell_block_of_plain_commands_runs_here_and_any_other_in_bash() -> None:
    """Continuations joined, a script's quoted lines kept whole, comments dropped; a pipe,
    a variable or a command other than ``piezohyst`` or ``python -c`` sends the block to
    ``bash``."""
    text = (
        'python -c "\nimport numpy as np\nprint(np.pi)"\n'
        "piezohyst fit run.csv \\\n    --model auto -o auto.json   # the choice\n"
    )
    assert _commands(text) == [
        ["python", "-c", "\nimport numpy as np\nprint(np.pi)"],
        ["piezohyst", "fit", "run.csv", "--model", "auto", "-o", "auto.json"],
    ]
    for other in (
        "piezohyst fit run.csv | tee out.txt",
        "piezohyst fit $RUN",
        "mkdir -p lib\npiezohyst fit run.csv",
        'python -c "print(\\"$HOME\\")"',
        'python -c "print(1)" > out.txt',
        'python -c "print(1)',
    ):
        assert _commands(other) is None, other
