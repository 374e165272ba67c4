"""The API reference of `import robot_calib`, generated from the docstrings with pdoc:
one HTML page per module of the public API (docs/api/index.html by default).

    .venv/bin/python scripts/api_reference.py [OUTPUT_FOLDER]

pdoc rather than Sphinx or mkdocstrings: it needs no configuration or site of its own,
reads the type hints and the numpy-style sections the docstrings use, and writes static
HTML in about two seconds; the reference is the docstrings, nothing written twice.
"""

from __future__ import annotations

import sys
from pathlib import Path

import robot_calib

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = ROOT / "docs" / "api"


def public_modules() -> tuple[str, ...]:
    """The modules that define the names `robot_calib` exports and the types its functions
    return (what a notebook user meets), each once."""
    from robot_calib.compensation import Compensation
    from robot_calib.flows.simulate import Simulation

    names = [getattr(robot_calib, n) for n in robot_calib.__all__ if not n.startswith("__")]
    returned = [Simulation, Compensation]  # what api.simulate and api.compensate return
    return tuple(dict.fromkeys(obj.__module__ for obj in [*names, *returned]))


def write_reference(output: Path) -> Path:
    """Write the reference into `output` (created); its index page."""
    import pdoc
    import pdoc.render

    pdoc.render.configure(docformat="numpy", search=False, show_source=False)
    pdoc.pdoc(*public_modules(), output_directory=output)
    return output / "index.html"


def main(argv: list[str]) -> int:
    output = Path(argv[0]) if argv else DEFAULT_OUTPUT
    index = write_reference(output)
    print(f"{index}: the API reference of {len(public_modules())} modules")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
