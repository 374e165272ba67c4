"""The API reference (scripts/api_reference.py, pdoc) documents every name `import
robot_calib` exports, with its docstring: a name added to `__all__` without a docstring, or
in a module the reference leaves out, fails here."""

from __future__ import annotations

import html
import inspect
import re
import sys
from pathlib import Path

import robot_calib

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))

from api_reference import public_modules, write_reference  # noqa: E402


def words(text: str) -> list[str]:
    """The words of `text` without markup or punctuation (as rendered or as written)."""
    return re.findall(r"[A-Za-z0-9]+", text)


def test_every_exported_name_is_in_the_reference_with_its_docstring(tmp_path: Path) -> None:
    index = write_reference(tmp_path)
    assert index.exists()
    pages = {m: (tmp_path / (m.replace(".", "/") + ".html")).read_text() for m in public_modules()}
    exported = [name for name in robot_calib.__all__ if not name.startswith("__")]
    assert len(exported) >= 12
    for name in exported:
        obj = getattr(robot_calib, name)
        doc = inspect.getdoc(obj)
        assert doc, f"{name}: no docstring"
        first_words = " ".join(words(doc)[:6])
        home = obj.__module__  # where it is defined, and documented
        assert home in pages, f"{name}: its module {home} is not in the reference"
        page = " ".join(words(html.unescape(re.sub(r"<[^>]+>", " ", pages[home]))))
        assert f'id="{name}"' in pages[home], f"{name}: not documented in {home}"
        assert first_words in page, f"{name}: docstring missing in {home}"
