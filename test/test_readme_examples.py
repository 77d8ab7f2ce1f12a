"""The README's worked examples, run as written, their printed lines checked.

An example is a fenced block right after a marker line ``<!-- example: NAME [slow] [rtol=X] [atol=Y] -->``:

* a ``console`` block: lines starting with ``$ `` are commands (run with bash from the repository root); the
  lines after a command, up to the next one, are lines its output (stdout and stderr) must contain, in that
  order, each somewhere in one output line. ``…`` inside an expected line stands for any text; a line that is
  only ``…`` stands for lines left out. Numbers must agree within ``rtol``/``atol`` (default: 1e-9 relative):
  other developers change the diagnosis' numbers, so the README states the tolerance the physics allows;
* a ``python`` block followed by a ``text`` block: the code run with this interpreter, the text its output.

Outputs go under ``out/`` in the README; here every ``out/`` is a fresh temporary folder (in the commands and in
the expected lines alike), so the test never writes into the checkout. The examples that start ROS or the
MuJoCo / Dask machinery are marked ``slow``; every example is cheap enough for the default run.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from conftest import REPO_ROOT, next_domain_id

README = REPO_ROOT / "README.md"
MARKER = re.compile(r"^<!--\s*example:\s*(?P<name>[\w-]+)(?P<opts>[^>]*)-->\s*$")
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Step:
    command: str
    expected: list[str] = field(default_factory=list)
    python: bool = False


@dataclass
class Example:
    name: str
    line: int
    steps: list[Step]
    slow: bool = False
    rtol: float = 1e-9
    atol: float = 0.0


def _fences(lines: list[str], start: int):
    """(info string, body lines, index after the closing fence) of the fenced block at or after ``start``."""
    i = start
    while i < len(lines) and not lines[i].startswith("```"):
        if lines[i].strip():
            return None
        i += 1
    if i >= len(lines):
        return None
    info = lines[i][3:].strip()
    j = i + 1
    while j < len(lines) and not lines[j].startswith("```"):
        j += 1
    return info, lines[i + 1:j], j + 1


def parse(text: str) -> list[Example]:
    lines = text.splitlines()
    out = []
    for k, line in enumerate(lines):
        m = MARKER.match(line)
        if not m:
            continue
        opts = m.group("opts").split()
        kw = dict(o.split("=", 1) for o in opts if "=" in o)
        ex = Example(m.group("name"), k + 1, [], slow="slow" in opts, rtol=float(kw.get("rtol", 1e-9)),
                     atol=float(kw.get("atol", 0.0)))
        block = _fences(lines, k + 1)
        assert block, f"README.md:{k + 1}: example {ex.name!r} is not followed by a fenced block"
        info, body, after = block
        if info.startswith("python"):
            expected = _fences(lines, after)
            assert expected and expected[0].startswith("text"), \
                f"README.md:{k + 1}: the python example {ex.name!r} needs a ```text block of its output after it"
            ex.steps.append(Step("\n".join(body), [x for x in expected[1] if x.strip()], python=True))
        else:
            assert info.startswith("console"), f"README.md:{k + 1}: example {ex.name!r}: ```console or ```python"
            cmd = None
            for b in body:
                if b.startswith("$ "):
                    cmd = Step(b[2:])
                    ex.steps.append(cmd)
                elif cmd is not None and cmd.command.endswith("\\") and not cmd.expected:
                    cmd.command = cmd.command[:-1] + " " + b.strip()
                elif cmd is not None and b.strip() and b.strip() != "…":
                    cmd.expected.append(b)
        assert ex.steps, f"README.md:{k + 1}: example {ex.name!r} has no command"
        out.append(ex)
    return out


EXAMPLES = parse(README.read_text())


def _pattern(expected: str) -> tuple[re.Pattern, list[float]]:
    """A regex for one expected line (text literal, whitespace runs free, ``…`` any text, numbers captured)."""
    parts, numbers, pos = [], [], 0
    for m in NUMBER.finditer(expected):
        parts.append(expected[pos:m.start()])
        parts.append(None)
        numbers.append(float(m.group()))
        pos = m.end()
    parts.append(expected[pos:])
    rx = []
    for p in parts:
        if p is None:
            rx.append(r"([-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?)")
            continue
        for j, chunk in enumerate(p.split("…")):
            if j:
                rx.append(".*?")
            rx.append(r"\s+".join(re.escape(w) for w in re.split(r"\s+", chunk)))
    return re.compile("".join(rx)), numbers


def _matches(expected: str, actual: str, rtol: float, atol: float) -> bool:
    rx, numbers = _pattern(expected.strip())
    for m in rx.finditer(actual):
        got = [float(g) for g in m.groups()]
        if all(abs(g - e) <= atol + rtol * abs(e) for g, e in zip(got, numbers)):
            return True
    # the regex is lazy: also try every start position for a number-tolerant match further along
    for start in range(1, len(actual)):
        m = rx.search(actual, start)
        if m is None:
            return False
        got = [float(g) for g in m.groups()]
        if all(abs(g - e) <= atol + rtol * abs(e) for g, e in zip(got, numbers)):
            return True
    return False


def check_output(expected: list[str], output: str, rtol: float, atol: float) -> None:
    """Every expected line, in order, matched by one output line (numbers within the tolerance)."""
    lines = output.splitlines()
    i = 0
    for e in expected:
        while i < len(lines) and not _matches(e, lines[i], rtol, atol):
            i += 1
        if i == len(lines):
            raise AssertionError(f"expected line not found (in order, rtol {rtol:g}, atol {atol:g}):\n  {e}\n"
                                 f"--- output ---\n{output[-6000:]}")
        i += 1


def _localize(s: str, out_dir: Path) -> str:
    return re.sub(r"(?<![\w./-])out/", f"{out_dir}/", s)


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH")}
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(next_domain_id()),
               PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    return env


def run_example(ex: Example, tmp_path: Path) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    env = _env()
    for step in ex.steps:
        if step.python:
            cmd = [sys.executable, "-c", _localize(step.command, out_dir)]
            shown = "python example"
        else:
            cmd = ["bash", "-c", _localize(step.command, out_dir)]
            shown = step.command
        res = subprocess.run(cmd, cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True, timeout=900, stdin=subprocess.DEVNULL)   # one stream: the order printed
        output = res.stdout
        assert res.returncode == 0, f"README example {ex.name!r}: `{shown}` exited {res.returncode}\n{output[-6000:]}"
        check_output([_localize(e, out_dir) for e in step.expected], output, ex.rtol, ex.atol)


@pytest.mark.parametrize("ex", [pytest.param(e, id=e.name, marks=[pytest.mark.slow] if e.slow else [])
                                for e in EXAMPLES])
def test_readme_example(ex, tmp_path):
    run_example(ex, tmp_path)


# -- the README's shape and the checker itself ------------------------------------------------------------------

def test_readme_is_short_and_every_subcommand_has_a_checked_example():
    text = README.read_text()
    assert len(text.splitlines()) <= 350
    commands = " ".join(s.command for e in EXAMPLES for s in e.steps)
    for sub in ("scripts/demo.sh", "bldc-actuator simulate", "bldc-actuator convert", "bldc-actuator diagnose",
                "bldc-actuator fleet", "bldc-actuator record-info", "bldc-actuator export-mujoco", "actuator_node",
                "bldc_actuator.mujoco.leg_example"):
        assert sub in commands, sub
    assert "bash scripts/demo.sh\nbash scripts/test.sh\n" in text          # the two commands, exactly


def test_readme_commands_write_only_under_out():
    """Examples write their outputs under out/ (git-ignored), never into the checkout's tracked tree."""
    assert "out/" in (REPO_ROOT / ".gitignore").read_text().split()
    for e in EXAMPLES:
        for s in e.steps:
            for flag in re.findall(r"(?:--out|--report|--json|--updated-params|--plot|--record|-o)\s+(\S+)",
                                   s.command):
                assert flag.startswith("out/"), (e.name, flag)
            for path in re.findall(r"dump_yaml\([^)]*\)\s*,\s*'([^']+)'", s.command):
                assert path.startswith("out/"), (e.name, path)


def test_the_checker_accepts_numbers_within_the_tolerance_and_refuses_others():
    out = "  coulomb_friction: coulomb_friction=0.05971±0.0001098; velocity error 28.25 -> 1.143 rad/s: confirmed\n"
    check_output(["coulomb_friction: coulomb_friction=0.0597±… -> … rad/s: confirmed"], out, 0.05, 0)
    with pytest.raises(AssertionError):
        check_output(["coulomb_friction: coulomb_friction=0.0650±…"], out, 0.05, 0)
    with pytest.raises(AssertionError):
        check_output(["coulomb_friction: … rejected"], out, 0.05, 0)
    with pytest.raises(AssertionError):                                   # order matters
        check_output(["b 2", "a 1"], "a 1\nb 2\n", 0, 0)
    check_output(["a 1", "b 2"], "x\na 1.0000000001\nb 2\n", 1e-9, 0)


def test_the_parser_reads_commands_continuations_and_python_blocks():
    text = ("<!-- example: x slow rtol=0.1 -->\n```console\n$ echo a \\\n  b\na b\n…\n$ true\n```\n\n"
            "<!-- example: y -->\n```python\nprint(1)\n```\n\n```text\n1\n```\n")
    x, y = parse(text)
    assert (x.name, x.slow, x.rtol) == ("x", True, 0.1)
    assert [s.command for s in x.steps] == ["echo a  b", "true"] and x.steps[0].expected == ["a b"]
    assert y.steps[0].python and y.steps[0].expected == ["1"]
