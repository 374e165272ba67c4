"""The package's exception types. Messages name the offending file, topic or value.

The CLI turns every `RobotCalibError` into a one-line message and exit status 2.
"""


class RobotCalibError(Exception):
    """Base class: bad input a user can fix (exit status 2 at the CLI)."""

    exit_status = 2


class RobotDescriptionError(RobotCalibError):
    """Unknown robot name, unreadable or malformed robot YAML."""


class ParameterError(RobotCalibError):
    """Unknown parameter name, wrong vector length, bad parameter file."""


class InputError(RobotCalibError):
    """Bad array shapes or values at a public boundary (CSV, bag, arguments)."""


class BagError(RobotCalibError):
    """Unreadable, truncated or existing bag file (MCAP), or a bad topic/type in one."""
