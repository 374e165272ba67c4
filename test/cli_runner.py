"""The real command line, as the tests run it.

`robot_calib(...)` runs `python -m robot_calib ARGS` in a subprocess: for the tests whose
point is a real process (exit status of the program, signals, limits, start-up, ROS
isolation between processes).

`cli(...)` runs the same `robot_calib.cli.main(ARGS)` in this process (no interpreter
start-up and imports, ~1-3 s per command on the 2-core test machine) and returns the same
CompletedProcess: exit status as `python -m robot_calib` gives it (main's status; argparse's
SystemExit; 1 with the traceback for an uncaught exception), and everything written to
file descriptors 1 and 2 while it ran (Python's and C's, e.g. rclpy's logging), in order.
Python warnings are printed to stderr as a fresh interpreter prints them. The package's
per-process state starts empty as in a new process (`_fresh_process_state`); the signal
handlers, sys.unraisablehook and the working directory main() changes are restored after.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import subprocess
import sys
import tempfile
import traceback
import warnings
from collections.abc import Iterator
from pathlib import Path


def robot_calib(
    *args: str, cwd: Path | None = None, timeout: float | None = None
) -> subprocess.CompletedProcess[str]:
    """`robot-calib ARGS...` in `cwd`: exit status, stdout and stderr as text."""
    return subprocess.run(
        [sys.executable, "-m", "robot_calib", *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=cwd,
        timeout=timeout,
    )


class _Captured:
    text = ""


@contextlib.contextmanager
def _fd_captured(fd: int) -> Iterator[_Captured]:
    """Everything written to file descriptor `fd` in the block, as text when it ends."""
    captured = _Captured()
    saved = os.dup(fd)
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), fd)
            yield captured
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            sink.seek(0)
            captured.text = sink.read().decode("utf-8", "replace")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _main_status(args: list[str]) -> int:
    """robot_calib.cli.main(args) as `python -m robot_calib` ends: its exit status."""
    from robot_calib import cli as cli_module

    try:
        return int(cli_module.main(args))
    except SystemExit as exc:  # argparse: --help, --version, usage errors
        if exc.code is None or isinstance(exc.code, int):
            return exc.code or 0
        print(exc.code, file=sys.stderr)
        return 1
    except Exception:  # noqa: BLE001 - reported as the interpreter reports it
        traceback.print_exc()
        return 1


@contextlib.contextmanager
def _fresh_process_state() -> Iterator[None]:
    """The package's per-process state empty for the block, as in a new process, and put
    back after: the outputs claimed new (atomic._NEW: a second command in one process
    would find its output claimed by the first), the signals received and held (cli, atomic),
    the robot descriptions learned from PARAMS.json sections (params_file._SECTIONS: a
    later command would not need the file's own section). bulk_decode._LAYOUTS is a pure
    cache of message layouts and stays."""
    from robot_calib import atomic
    from robot_calib import cli as cli_module
    from robot_calib.identify import params_file

    states = (atomic._NEW, atomic._held, cli_module._SIGNALLED, params_file._SECTIONS)
    saved = [state.copy() for state in states]
    for state in states:
        state.clear()
    try:
        yield
    finally:
        for state, before in zip(states, saved):
            state.clear()
            if isinstance(state, list):
                state.extend(before)
            else:
                state.update(before)


def cli(
    *args: str, cwd: Path | None = None, timeout: float | None = None
) -> subprocess.CompletedProcess[str]:
    """`robot-calib ARGS...` in `cwd`, run in this process by `robot_calib.cli.main`: exit
    status, stdout and stderr as text, as `robot_calib(...)` gives them. `timeout` is
    accepted for the same signature and not enforced."""
    del timeout
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    hook, here = sys.unraisablehook, os.getcwd()
    old_out, old_err = sys.stdout, sys.stderr
    old_out.flush()
    old_err.flush()
    with (
        _fd_captured(1) as out,
        _fd_captured(2) as err,
        open(1, "w", encoding="utf-8", buffering=1, closefd=False) as new_out,
        open(2, "w", encoding="utf-8", buffering=1, closefd=False) as new_err,
    ):
        sys.stdout, sys.stderr = new_out, new_err
        try:
            with warnings.catch_warnings():
                # a fresh interpreter's filters, warnings printed to stderr
                warnings.resetwarnings()
                for category in (
                    DeprecationWarning,
                    PendingDeprecationWarning,
                    ImportWarning,
                    ResourceWarning,
                ):
                    warnings.simplefilter("ignore", category)
                warnings.showwarning = _show_warning
                if cwd is not None:
                    os.chdir(cwd)
                with _fresh_process_state():
                    status = _main_status(list(args))
                    gc.collect()  # what a process says as it ends ("Exception ignored in ...")
        finally:
            sys.stdout, sys.stderr = old_out, old_err
            os.chdir(here)
            sys.unraisablehook = hook
            for number, handler in handlers.items():
                signal.signal(number, handler)
    command = [sys.executable, "-m", "robot_calib", *args]
    return subprocess.CompletedProcess(command, status, out.text, err.text)
