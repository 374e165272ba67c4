"""Model names as people read them in the reports: a name such as
`geometric+backlash:4+joint_harmonics:2:orders=12,20` may break between its terms (after a
'+') or between a term's joints and orders (after a ','), never inside a term's name.
Used by the figures (labels on lines, `wrap_name`) and both reports (break opportunities,
`with_breaks`)."""

from __future__ import annotations

#: characters after which a model name may break: between terms, between joints or orders
BREAK_AFTER = ("+", ",")


def name_pieces(name: str, after: str = "".join(BREAK_AFTER)) -> list[str]:
    """`name` cut after every character of `after` (default: BREAK_AFTER): the pieces that
    may not break ('geometric+', 'backlash:4+', 'joint_harmonics:2:orders=12,', '20');
    joined they give `name` back."""
    pieces, start = [], 0
    for k, char in enumerate(name):
        if char in after:
            pieces.append(name[start : k + 1])
            start = k + 1
    if start < len(name) or not pieces:
        pieces.append(name[start:])
    return pieces


def wrap_name(name: str, width: int = 24) -> str:
    """`name` on lines of at most `width` characters where its pieces allow, joined by
    newlines (a label for a plot): greedily filled with whole terms (cut after '+'), a
    term longer than `width` cut after its commas too; a piece longer than `width` stays
    whole on a line of its own."""
    lines: list[str] = []
    for term in name_pieces(name, "+"):
        pieces = [term] if len(term) <= width else name_pieces(term, ",")
        for piece in pieces:
            if lines and len(lines[-1]) + len(piece) <= width:
                lines[-1] += piece
            else:
                lines.append(piece)
    return "\n".join(lines)


def with_breaks(escaped_name: str, mark: str = "<wbr>") -> str:
    """An (already HTML-escaped) model name with `mark` after every BREAK_AFTER character:
    the only places a browser may break it (with CSS `word-break: keep-all` and
    `overflow-wrap: normal` on its element, `MODEL_CSS`). '+' and ',' survive HTML
    escaping unchanged."""
    return "".join(piece + mark for piece in name_pieces(escaped_name)).removesuffix(mark)


#: the CSS class of an element holding a model name (HTML report)
MODEL_CLASS = "model"
MODEL_CSS = f".{MODEL_CLASS}{{overflow-wrap:normal;word-break:keep-all;white-space:normal}}"
