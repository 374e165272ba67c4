"""`Log`: how the core hands its progress and warning lines to a front end.

A core function that has something to say takes `log: Log | None`: a callable that takes
one line ('warning: ...' for a warning, else progress). The command line prints them, the
nodes log them at their level, a notebook may collect them; None says nothing.
"""

from __future__ import annotations

from collections.abc import Callable

Log = Callable[[str], None]
