"""The package's exception types. Messages name the offending file, topic or value.

The CLI turns every `RobotCalibError` into a one-line message and its exit status: 2 for
bad input, 3 for a fit that ran to its end with a nonsense result (`ImplausibleError`).
"""

from __future__ import annotations

import ast
import difflib
import re
from collections.abc import Iterable, Sequence

_UNSET = object()


def param(name: str, value: object = _UNSET) -> str:
    """How a message of the core names a caller's option: its Python keyword in backquotes,
    `` `name` `` or `` `name=value` `` with the value as Python writes it
    (`` `model='geometric+x'` ``, `` `force=True` ``). The command line prints the verb's
    flag instead (`--model geometric+x`, `--force`: cli/flags.py); the core never names a
    flag its caller may not have."""
    return f"`{name}`" if value is _UNSET else f"`{name}={value!r}`"


#: a keyword in a message as `param` writes it: group 1 its name, group 2 its value as
#: Python writes it (None: the name alone); the front ends rewrite it in their terms
KEYWORD = re.compile(r"`([a-z_][a-z0-9_]*)(?:=([^`]*))?`")


#: keywords whose option only one command has: that command, for a front end without it
#: (another verb of the command line, a node)
ELSEWHERE = {"stream": "robot-calib calibrate --stream"}


def keyword_value(text: str) -> object:
    """The value of a keyword as `param` wrote it (its repr read back), else `text`."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


#: the end of the message of an output that exists (the overwrite policy)
EXISTS = f"exists; will not overwrite it (use {param('force', True)})"


class RobotCalibError(Exception):
    """Base class: bad input a user can fix (exit status 2 at the CLI)."""

    exit_status = 2
    kind = "error"  # the CLI's line: 'robot-calib VERB: KIND: message'


class ImplausibleError(RobotCalibError):
    """A fit that ran to its end but whose result is nonsense (PARAMS.json `plausible:
    false`: readings in degrees, a residual far beyond the noise, parameters beyond physics,
    worse than the simpler model it extends): exit status 3; the file is written for
    inspection, and `predict`, `compensate`, `export` refuse it without --force."""

    exit_status = 3
    kind = "fitted, implausible"


class WrittenFileError(RobotCalibError):
    """A file this tool was about to write that its own reader refuses (a bug, not bad
    input): exit status 1, nothing written."""

    exit_status = 1
    kind = "internal error (please report it)"


class RobotDescriptionError(RobotCalibError):
    """Unknown robot name, unreadable or malformed robot YAML."""


class ParameterError(RobotCalibError):
    """Unknown parameter name, wrong vector length, bad parameter file."""


class InputError(RobotCalibError):
    """Bad array shapes or values at a public boundary (CSV, bag, arguments)."""


class BagError(RobotCalibError):
    """Unreadable, truncated or existing bag file (MCAP), or a bad topic/type in one."""


class TruncatedBagError(BagError):
    """A bag whose writer did not close it (killed): no footer, its closed chunks readable."""


def check_keys(
    keys: Iterable[object],
    known: Sequence[str],
    where: str,
    error: type[RobotCalibError] = InputError,
    what: str = "key",
) -> None:
    """Raise `error` naming the first of `keys` not in `known`, with the closest known one
    as a hint ("did you mean 'mass'?") or the known ones: a misspelt key or option must not
    be silently ignored."""
    for key in keys:
        if key in known:
            continue
        close = difflib.get_close_matches(str(key), known, n=1)
        hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known) or 'none'}"
        raise error(f"{where}: unknown {what} {str(key)!r} ({hint})")
