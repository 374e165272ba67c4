"""The core's messages in the command line's terms: a caller's option named in a message as
its Python keyword in backquotes (`errors.param`: `` `model='geometric+x'` ``, `` `force=True` ``,
`` `tracker_sigma_m` ``) is printed as the verb's flag (`--model geometric+x`, `--force`,
`--tracker-accuracy`). A notebook user is told about the keyword they typed, a command-line
user about the flag.

The keywords are the argparse destinations of the verb's options (`--floor-z` -> `floor_z`)
plus `ALIASES`, where the Python API names an option otherwise. A name the verb has no flag
for stays as written.
"""

from __future__ import annotations

import argparse
import re
import shlex

from robot_calib.errors import ELSEWHERE, KEYWORD, keyword_value

# Python keyword -> the argparse destination of the flag that sets it (where they differ)
ALIASES = {
    "tracker_sigma_m": "tracker_accuracy",  # rc.diagnose(tracker_sigma_m=) [m]; the flag in mm
    "separator": "sep",
    "n_poses": "poses",
    "floor_z_m": "floor_z",
    "fraction": "holdout",  # split_recording(fraction=): `split --holdout`
    "targets": "target",  # CsvFormat's fields: `import --target`, `--reference`
    "references": "reference",
    "header=False": "no_header",  # CsvFormat(header=False): `import --no-header`
}

# values the command line spells otherwise, by destination
SPELLED = {"sep": {"\t": "tab"}}

_flags: dict[str, str] = {}  # destination -> its long option, of the verb being run
_negated: dict[str, str] = {}  # destination -> its --no-X option (a store_false flag)


def learn(parser: argparse.ArgumentParser, verb: str) -> None:
    """Take the flags of `verb`'s parser (a sub-command of `parser`) and `parser`'s own, in
    place of those of a verb run before in this process."""
    _flags.clear()
    _negated.clear()
    _take(parser, verb)


def _take(parser: argparse.ArgumentParser, verb: str) -> None:
    for action in parser._actions:  # argparse has no public accessor for its actions
        if isinstance(action, argparse._SubParsersAction):
            if verb in action.choices:
                _take(action.choices[verb], verb)
            continue
        # as the verb's --help spells it first (-o for -o/--output)
        longs = list(action.option_strings)
        if not longs or action.dest in ("help", argparse.SUPPRESS):
            continue
        if isinstance(action, argparse._StoreFalseAction):
            _negated[action.dest] = longs[0]
        else:
            _flags.setdefault(action.dest, longs[0])


def in_flags(message: str) -> str:
    """`message` with every keyword the verb has a flag for written as that flag."""
    return KEYWORD.sub(_as_flag, message)


def _as_flag(match: re.Match[str]) -> str:
    name, text = match.group(1), match.group(2)
    spelled = ALIASES.get(f"{name}={text}")
    if spelled in _flags:  # a keyword whose value is a flag of its own (--no-header)
        return _flags[spelled]
    dest = name if name in _flags or name in _negated else ALIASES.get(name, name)
    flag = _flags.get(dest)
    if flag is None and dest not in _negated and name in ELSEWHERE:
        return ELSEWHERE[name]
    if text is None:
        return flag or _negated.get(dest) or match.group(0)
    value = keyword_value(text)
    if value is True and flag:
        return flag
    if value is False and dest in _negated:
        return _negated[dest]
    if flag is None or isinstance(value, bool):
        return match.group(0)
    if isinstance(value, list | tuple):
        return " ".join([flag, *(shlex.quote(str(v)) for v in value)])
    text = SPELLED.get(dest, {}).get(value, value) if isinstance(value, str) else value
    return f"{flag} {shlex.quote(str(text))}"
