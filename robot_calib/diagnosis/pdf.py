"""A report's HTML printed to PDF by a headless Chromium (the browser the report's
rendering test uses; no second layout engine to keep in step with the HTML: what the
browser shows is what the PDF holds). Debian's package `chromium` provides it."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

from robot_calib.errors import InputError, param

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: Chromium's switches (each given with two dashes): headless, no sandbox (root in a
#: container), no GPU, nothing fetched from the network, no page header or footer
SWITCHES = (
    "headless",
    "no-sandbox",
    "disable-gpu",
    "no-first-run",
    "disable-background-networking",
    "disable-component-update",
    "disable-sync",
    "no-pdf-header-footer",
)
PRINT_SECONDS = 120.0  # a report of a few MB prints in 2-5 s; a hung browser is stopped


def browser() -> str:
    """The Chromium on PATH; InputError saying how to get one when there is none (asked
    before any work: a PDF that cannot be printed is known at once)."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    raise InputError(
        f"{param('pdf', True)}: no Chromium on PATH to print the report with "
        "(Debian: apt-get install chromium)"
    )


def print_pdf(html: Path, pdf: Path) -> None:
    """Print the HTML file `html` (self-contained) to `pdf` (A4, the page's own
    background); InputError with the browser's last line when it fails."""
    with tempfile.TemporaryDirectory(prefix="robot-calib-chromium-") as profile:
        switches = [*SWITCHES, f"user-data-dir={profile}", f"print-to-pdf={pdf}"]
        command = [browser(), *(f"--{s}" for s in switches), html.resolve().as_uri()]
        try:
            done = subprocess.run(
                command, capture_output=True, text=True, timeout=PRINT_SECONDS, check=False
            )
        except subprocess.TimeoutExpired:
            raise InputError(f"{pdf}: Chromium did not print within {PRINT_SECONDS:g} s") from None
    if done.returncode != 0 or not pdf.is_file() or pdf.stat().st_size == 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise InputError(f"{pdf}: Chromium could not print the report ({last})")
