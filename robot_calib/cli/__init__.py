"""`robot-calib` command line: parse, call the flows (robot_calib/flows/), print, map errors
to exit codes. One module per verb (`registry.VERBS`, in --help order), the options several
verbs share in `options`, what they do with them in `common`.

Every bad input ends in one line on stderr naming the file/value and exit status 2; a
calibration that ran to its end with a nonsense result (PARAMS.json `plausible: false`,
written for inspection) in "fitted, implausible: REASON" and exit status 3; Ctrl-C,
SIGTERM or SIGHUP in "interrupted" and exit status 130, nothing left behind.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import warnings
from collections.abc import Sequence
from functools import partial
from typing import Any, NoReturn

from robot_calib import program_and_verb
from robot_calib.atomic import INTERRUPTS
from robot_calib.cli.flags import in_flags, learn
from robot_calib.cli.options import OVERWRITE_POLICY
from robot_calib.cli.registry import VERB_NAMES, build_parser
from robot_calib.errors import RobotCalibError

__all__ = ["OVERWRITE_POLICY", "build_parser", "main", "run"]

# signals received (SIGINT, SIGTERM, SIGHUP) while a verb runs: the list every final rename
# of an output checks first (`atomic.INTERRUPTS`)
_SIGNALLED = INTERRUPTS


def _interrupt(signum: int, _frame: object) -> NoReturn:
    """Ctrl-C, SIGTERM and SIGHUP (the terminal closed): unwind (staged outputs are
    removed), 'interrupted', exit 130."""
    _SIGNALLED.append(signum)
    raise KeyboardInterrupt


def _ignore_interrupt_in_callback(unraisable: Any) -> None:
    """A KeyboardInterrupt raised by `_interrupt` inside a callback Python cannot raise from
    (a weakref or __del__: 'Exception ignored in ... WeakSet') is not printed: the signal
    is recorded and `main` exits 130 after all (was: the program went on to exit 0)."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _SIGNALLED:
        return
    sys.__unraisablehook__(unraisable)


def main(argv: Sequence[str] | None = None) -> int:
    """`robot-calib ARGV...` (None: the program's arguments): the verb's exit status; a
    package error (RobotCalibError) as one line and its status, an interruption as 130."""
    from robot_calib import _interrupted_while_starting

    argv = list(sys.argv[1:] if argv is None else argv)
    named = argv[0] if argv and argv[0] in VERB_NAMES else None  # only its options built
    parser = build_parser(named)
    args = parser.parse_args(argv)
    args.argv = argv  # the exact command, for the reports' header
    learn(parser, args.command)  # the core's messages name keywords: printed as its flags
    signal.signal(signal.SIGTERM, _interrupt)
    if signal.getsignal(signal.SIGHUP) is signal.SIG_DFL:  # not under nohup (ignored)
        signal.signal(signal.SIGHUP, _interrupt)
    if signal.getsignal(signal.SIGINT) in (  # not when ignored
        signal.default_int_handler,
        _interrupted_while_starting,  # robot_calib/__init__.py's, while the modules loaded
    ):
        signal.signal(signal.SIGINT, _interrupt)
    sys.unraisablehook = _ignore_interrupt_in_callback
    with warnings.catch_warnings():  # restored after the verb: callers run `main` in-process
        warnings.showwarning = partial(_warning_line, args.command)
        return _run_verb(args)


def _warning_line(
    verb: str, message: Warning | str, category: type[Warning], *_: Any, **__: Any
) -> None:
    """A Python warning (numpy's, scipy's, the package's RuntimeWarning) as one line
    'warning: MESSAGE' like the verb's own warnings (`verb`: kept for the signature),
    never a source line or a file path ('robot-calib VERB: ...' is the line of an error)."""
    del verb
    text = in_flags(" ".join(str(message).split()))
    print(f"warning: {text}", file=sys.stderr)


def _run_verb(args: argparse.Namespace) -> int:
    """The verb of `args`: its exit status (see `main`)."""
    try:
        if args.base_link or args.tip_link:  # carried in the robot reference (PARAMS.json)
            from robot_calib.kinematics.urdf import urdf_reference

            args.robot = urdf_reference(args.robot or "", args.base_link, args.tip_link)
        status = int(args.func(args))
        if _SIGNALLED:  # the interrupt fell in a callback that swallowed it
            raise KeyboardInterrupt
        return status
    except BaseException as exc:
        # A signal can surface as another exception when it lands in a C extension's call
        # back into Python (e.g. an rclpy callback): it is still an interruption.
        if isinstance(exc, KeyboardInterrupt) or _SIGNALLED:
            print(f"robot-calib {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, RobotCalibError):
            print(f"robot-calib {args.command}: {exc.kind}: {in_flags(str(exc))}", file=sys.stderr)
            return exc.exit_status
        raise


def run() -> NoReturn:
    """The `robot-calib` program (console script, `python -m robot_calib`): `main` on the
    program's arguments, then exit with its status. Standard output failing never stops the
    work (its files are written): the status is then 141 when its reader went away
    (`| head`), 2 with one line when it cannot be written (a full disk), unless the verb's
    own is an error. Everything this process made is then frozen for the garbage collector
    (`gc.freeze`): the interpreter's tear-down of scipy's and matplotlib's modules
    otherwise took 0.3-0.4 s of every run, after the files were written. Not in `main`,
    which callers run in-process (the tests)."""
    import gc

    _open_standard_streams()
    stdout = _Guarded(sys.stdout, 1)
    sys.stdout = stdout
    sys.stderr = _Guarded(sys.stderr, 2)
    status = main()
    stdout.flush()
    if stdout.lost is not None and status == 0:
        if isinstance(stdout.lost, BrokenPipeError):  # `| head`: the shell's status for it
            status = 128 + signal.SIGPIPE
        else:
            print(
                f"{program_and_verb()}: cannot write to standard output: "
                f"{stdout.lost.strerror or stdout.lost} (its files are written)",
                file=sys.stderr,
            )
            status = 2
    gc.freeze()
    sys.exit(status)


def _open_standard_streams() -> None:
    """Python's streams for standard output and error the caller closed (`>&-`, `2>&-`:
    None, was an AttributeError traceback and exit 120, and stderr's lines printed into
    stdout), on the /dev/null that `robot_calib._open_closed_descriptors` put there."""
    if sys.stdout is None:
        sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115 - the program's own stdout
    if sys.stderr is None:
        sys.stderr = open(2, "w", closefd=False, errors="backslashreplace")  # noqa: SIM115


class _Guarded:
    """Standard output or error (`stream` on descriptor `fd`) whose write or flush failure
    (`| head` gone, a full disk, `2>/dev/full`) is remembered (`lost`: the first) and sends
    the descriptor to /dev/null, the buffer emptied there (a failed line stays buffered and
    failed again at every flush and at exit): the command runs on and writes its files
    (was: a failing stdout stopped it where it printed, calibrate and run wrote nothing; a
    failing stderr was a traceback nobody could see, exit 1). `run` turns stdout's `lost`
    into its exit status; stderr's messages cannot be read anywhere."""

    def __init__(self, stream: Any, fd: int) -> None:  # noqa: ANN401 - a text stream
        self._stream, self._fd = stream, fd
        self.lost: OSError | None = None

    def write(self, text: str) -> int:
        try:
            self._stream.write(text)
        except OSError as exc:
            self._drop(exc)
        return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            self._drop(exc)

    def _drop(self, error: OSError) -> None:
        if self.lost is None:
            self.lost = error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, self._fd)
        os.close(devnull)
        with contextlib.suppress(OSError):
            self._stream.flush()  # the buffered text now goes to /dev/null

    def __getattr__(self, name: str) -> Any:  # noqa: ANN401 - the stream's own attributes
        return getattr(self._stream, name)
