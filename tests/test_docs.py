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
for each of the ~40 documented commands. Every other line runs in ``bash``; the
installed console script itself is run as a subprocess in tests/cli.
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


def _run_shell(block: Block, cwd: Path, where: str) -> None:
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
