"""The core speaks in Python terms: no string the core can raise, warn or log names a
command-line flag (a notebook user never typed `--model`); it names the keyword in
backquotes (`errors.param`), and the command line prints its flag instead (cli/flags.py).

Every string literal of every module outside `cli/`, `nodes/` and the console entry is read
with `ast` (docstrings aside: they document the command line too); only a whole command for
the reader to run ('robot-calib export ... --format urdf' in a report, `robot-calib repair
X -o FIXED.mcap` in a message) may carry flags."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from cli_runner import cli

import robot_calib

PACKAGE = Path(robot_calib.__file__).parent
FRONT_ENDS = ("cli", "nodes")
CONSOLE_ENTRY = ("__init__.py", "__main__.py")
# a whole command for the reader to run, in backquotes
COMMAND = re.compile(r"`robot-calib [^`]*`")
# a long flag (--model) or a short one (-o) followed by a space or the end
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]+|(?<![\w-])-[a-zA-Z](?=\s|$)")


def core_modules() -> list[Path]:
    return sorted(
        path
        for path in PACKAGE.rglob("*.py")
        if path.relative_to(PACKAGE).parts[0] not in FRONT_ENDS
        and not (path.parent == PACKAGE and path.name in CONSOLE_ENTRY)
    )


def docstrings(tree: ast.Module) -> set[int]:
    """ids of the docstring constants of the module, its classes and functions."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                found.add(id(body[0].value))
    return found


def flag_strings(path: Path) -> list[str]:
    """'LINE: text' of every string literal of `path` naming a flag."""
    tree = ast.parse(path.read_text(), str(path))
    skip = docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            parts = [v.value for v in node.values if isinstance(v, ast.Constant)]
            for value in node.values:
                skip.add(id(value))
            text = "{}".join(str(p) for p in parts)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if id(node) in skip:
                continue
            text = node.value
        else:
            continue
        text = COMMAND.sub("", text)  # a whole command to run may carry its flags
        if text.startswith("robot-calib ") or not FLAG.search(text):
            continue
        found.append(f"{node.lineno}: {text[:100]!r}")
    return sorted(found, key=lambda line: int(line.split(":")[0]))


def test_the_walk_reads_the_core_and_finds_a_flag_where_there_is_one(tmp_path: Path) -> None:
    """The check can fail: a module with a flag in an error is found, its docstring is not."""
    assert len(core_modules()) > 100
    assert all("cli" not in p.relative_to(PACKAGE).parts for p in core_modules())
    sample = tmp_path / "sample.py"
    sample.write_text(
        '"""Docstring naming --model is fine."""\n'
        "def f(spec):\n"
        '    """So is this: --force."""\n'
        '    raise ValueError(f"--model {spec}: unknown")\n'
        'HINT = "a wrong --robot?"\n'
        'NEXT = "robot-calib export p.json --format urdf"\n'
        'SHORT = f"-o {spec}: names a file"\n'
        'DASH = "x-y z - w, -1"\n'
        'RUN = f"truncated: run `robot-calib repair {spec} -o FIXED.mcap` first"\n'
    )
    assert [line.split(":")[0] for line in flag_strings(sample)] == ["4", "5", "7"]


@pytest.mark.parametrize("path", core_modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_core_message_names_a_command_line_flag(path: Path) -> None:
    assert flag_strings(path) == []


def test_the_python_caller_reads_keywords_and_the_command_line_flags(tmp_path: Path) -> None:
    """One error, two front ends: the keyword in Python, the flag at the command line."""
    from robot_calib import api
    from robot_calib.errors import InputError

    bag = PACKAGE.parent / "bags" / "paper_test3.mcap"
    recording = api.read_recording(bag, robot="kr5_sixx_r650")
    with pytest.raises(InputError, match=r"`model='geometric\+frobnicate:4'`: unknown effect"):
        api.calibrate(recording, "kr5_sixx_r650", model="geometric+frobnicate:4")
    run = cli(
        "calibrate", str(bag), "--model", "geometric+frobnicate:4", "-o", "p.json", cwd=tmp_path
    )
    assert run.returncode == 2
    assert "--model geometric+frobnicate:4: unknown effect" in run.stderr
    assert "`" not in run.stderr


@pytest.mark.parametrize(
    ("verb", "message", "printed"),
    [
        ("calibrate", "`model='geometric+x'`: unknown", "--model geometric+x: unknown"),
        ("calibrate", "use `force=True`", "use --force"),
        ("import", "give `header=False`", "give --no-header"),
        ("import", "give `separator='\\t'`", "give --sep tab"),
        ("import", "the `targets` names", "the --target names"),
        ("split", "`fraction=1.5`: a fraction", "--holdout 1.5: a fraction"),
        ("calibrate", "pairs badly: use `stream=True`", "pairs badly: use --stream"),
        (
            "score",
            "pairs badly: use `stream=True`",
            "pairs badly: use robot-calib calibrate --stream",
        ),
        ("score", "a keyword of no verb `frobnicate=3`", "a keyword of no verb `frobnicate=3`"),
    ],
)
def test_each_keyword_is_printed_as_the_verbs_flag(verb: str, message: str, printed: str) -> None:
    """The command line's rewrite (cli/flags.py) from the verb's own parser: its flags, the
    aliases where Python names an option otherwise, another verb's command where this one
    has no such option."""
    from robot_calib.cli import flags
    from robot_calib.cli.registry import build_parser

    flags.learn(build_parser("compensate"), "compensate")  # another verb's flags: forgotten
    flags.learn(build_parser(verb), verb)
    assert flags.in_flags(message) == printed
