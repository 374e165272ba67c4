"""The README's walk-through runs as written.

Every fenced ```bash block of the README's section "## Calibrate your robot" is run, the
blocks of one "### " example in order, in a fresh folder of their own, as `bash -e -o
pipefail`: a command that exits non-zero fails its example's test. The folder looks like
the repository's root to the commands (`docs`, `datasets` and `bags` link to this tree's),
and `robot-calib` is the script of this test's environment (first on PATH; where the
environment has no console script, a wrapper running `python -m robot_calib`).

A ```bash block that is not run, in the walk-through or elsewhere, says why, invisibly, on
the line before its opening fence: `<!-- not run: REASON -->` (or, for a block that must
keep its place at the top of the file, on the line after its closing fence:
`<!-- not run (above): REASON -->`). Nothing is skipped silently: a bash block with neither
fails test_every_bash_block_is_run_or_says_why.

The examples run two at a time (each is mostly single-threaded); all of them take about
30-40 s on 2 cores.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
WALKTHROUGH = "## Calibrate your robot"
LINKED = ("docs", "datasets", "bags")  # what the commands read, relative to the root
NOT_RUN = re.compile(r"^<!--\s*not run:\s*(\S.*?)\s*-->$")
NOT_RUN_ABOVE = re.compile(r"^<!--\s*not run \(above\):\s*(\S.*?)\s*-->$")
BLOCK_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class Block:
    """One fenced code block: where it starts (1-based line of its opening fence), its
    language, its text, the `## ` and `### ` headings it is under, and why it is not run
    (None: no such comment)."""

    line: int
    lang: str
    text: str
    section: str
    example: str
    not_run: str | None

    @property
    def runs(self) -> bool:
        return self.lang == "bash" and self.section == WALKTHROUGH and self.not_run is None


def parse(text: str) -> list[Block]:
    """The fenced blocks of a Markdown text, with their headings and not-run reasons."""
    lines = text.splitlines()
    blocks: list[Block] = []
    section = example = ""
    k = 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("```"):
            start, lang = k, line[3:].strip()
            end = start + 1
            while end < len(lines) and not lines[end].startswith("```"):
                end += 1
            before = NOT_RUN.match(lines[start - 1].strip()) if start > 0 else None
            after = NOT_RUN_ABOVE.match(lines[end + 1].strip()) if end + 1 < len(lines) else None
            reason = before or after
            blocks.append(
                Block(
                    start + 1,
                    lang,
                    "\n".join(lines[start + 1 : end]) + "\n",
                    section,
                    example,
                    reason.group(1) if reason else None,
                )
            )
            k = end + 1
            continue
        if line.startswith("## "):
            section, example = line.strip(), ""
        elif line.startswith("### "):
            example = line[4:].strip()
        k += 1
    return blocks


BLOCKS = parse(README.read_text(encoding="utf-8"))
EXAMPLES: dict[str, list[Block]] = {}
for _block in BLOCKS:
    if _block.runs:
        EXAMPLES.setdefault(_block.example, []).append(_block)


def test_every_bash_block_is_run_or_says_why() -> None:
    shell = [b for b in BLOCKS if b.lang in ("bash", "sh", "shell", "console")]
    assert all(b.lang == "bash" for b in shell), "shell blocks are ```bash"
    silent = [b.line for b in shell if not b.runs and b.not_run is None]
    assert silent == [], f"README.md lines {silent}: not run, and no <!-- not run: why -->"
    # the walk-through has its examples, each with commands that run
    assert all(name for name in EXAMPLES), "a walk-through block outside any ### example"
    assert len(EXAMPLES) >= 6, sorted(EXAMPLES)
    assert all("robot-calib " in "".join(b.text for b in EXAMPLES[e]) for e in EXAMPLES)


def test_the_readme_names_no_issue_numbers() -> None:
    text = README.read_text(encoding="utf-8")
    assert re.findall(r"(?i)\bissues? *#?\d+", text) == []


def test_the_parser_finds_reasons_and_headings() -> None:
    text = (
        "# t\n\n```bash\ntop\n```\n<!-- not run (above): set-up -->\n\n## Calibrate your robot\n"
        "### One\n```bash\na\n```\n<!-- not run: a robot -->\n```bash\nb\n```\n"
        "## Reference\n```bash\nc\n```\n"
    )
    top, a, b, c = parse(text)
    assert (top.not_run, top.runs) == ("set-up", False)
    assert (a.example, a.runs, a.text) == ("One", True, "a\n")
    assert (b.not_run, b.runs, b.line) == ("a robot", False, 14)
    assert (c.section, c.runs, c.not_run) == ("## Reference", False, None)


def _bin_dir(folder: Path) -> Path:
    """A folder whose `robot-calib` is this environment's."""
    here = Path(sys.executable).parent
    if (here / "robot-calib").exists():
        return here
    folder.mkdir(parents=True, exist_ok=True)
    wrapper = folder / "robot-calib"
    wrapper.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m robot_calib "$@"\n')
    wrapper.chmod(0o755)
    return folder


@dataclass(frozen=True)
class Outcome:
    failure: str | None  # None: every block exited 0
    seconds: float


def run_example(blocks: list[Block], folder: Path, bin_dir: Path) -> Outcome:
    """The blocks of one example in order, in `folder`; the first failure ends it."""
    folder.mkdir(parents=True)
    for name in LINKED:
        (folder / name).symlink_to(ROOT / name, target_is_directory=True)
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(bin_dir), env.get("PATH", "")])
    python_path = [str(ROOT), *filter(None, [env.get("PYTHONPATH")])]
    env["PYTHONPATH"] = os.pathsep.join(python_path)
    start = time.perf_counter()
    for block in blocks:
        proc = subprocess.run(
            ["bash", "-e", "-o", "pipefail", "-c", block.text],
            cwd=folder,
            env=env,
            capture_output=True,
            text=True,
            check=False,
            timeout=BLOCK_TIMEOUT_S,
        )
        if proc.returncode != 0:
            return Outcome(
                f"README.md line {block.line}: exit {proc.returncode}\n{block.text}"
                f"--- stderr (end) ---\n{proc.stderr[-3000:]}",
                time.perf_counter() - start,
            )
    return Outcome(None, time.perf_counter() - start)


@pytest.fixture(scope="module")
def outcomes(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Outcome]:
    """The examples this session selected (all, unless -k), run two at a time."""
    selected = {
        item.callspec.params["example"]
        for item in request.session.items
        if item.name.startswith("test_walkthrough_example") and hasattr(item, "callspec")
    }
    names = [name for name in EXAMPLES if name in selected]
    base = tmp_path_factory.mktemp("readme")
    bin_dir = _bin_dir(base / "bin")
    with ThreadPoolExecutor(2) as pool:
        results = pool.map(
            lambda k: run_example(EXAMPLES[names[k]], base / f"example{k}", bin_dir),
            range(len(names)),
        )
        return dict(zip(names, results))


@pytest.mark.parametrize("example", list(EXAMPLES))
@pytest.mark.slow
def test_walkthrough_example_runs_as_written(example: str, outcomes: dict[str, Outcome]) -> None:
    outcome = outcomes[example]
    assert outcome.failure is None, outcome.failure
