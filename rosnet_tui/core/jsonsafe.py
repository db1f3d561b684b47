"""JSON from outside (peer records, saved results): decoded with bounded depth, each key once.

The standard decoder recurses once per nesting level: a few thousand brackets (a few KB) exhaust
Python's stack and raise RecursionError; an integer of more than 4,300 digits raises a plain
ValueError. :func:`loads_bounded` turns all of that into :class:`JsonInputError` with a short
reason, checking the depth before decoding.
"""

from __future__ import annotations

import json
from typing import Any

DEFAULT_MAX_DEPTH = 64


class JsonInputError(ValueError):
    """JSON text we will not use; the message says why in a few words."""


def nesting_problem(text: str, limit: int = DEFAULT_MAX_DEPTH) -> str | None:
    """Why *text* nests arrays/objects too deeply (None: it does not). Strings are skipped."""
    depth = 0
    in_string = escaped = False
    for c in text:
        if in_string:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            if depth > limit:
                return f"nested more than {limit} levels deep"
        elif c in "]}":
            depth -= 1
    return None


def _once(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise JsonInputError(f"the key {k[:40]!r} appears twice (which one is meant?)")
        out[k] = v
    return out


def loads_bounded(text: str, *, max_depth: int = DEFAULT_MAX_DEPTH,
                  unique_keys: bool = True) -> Any:
    """Decode *text*; JsonInputError (only) for anything that is not plain JSON of bounded
    depth (with each key of an object once, when *unique_keys*)."""
    why = nesting_problem(text, max_depth)
    if why:
        raise JsonInputError(why)
    try:
        return json.loads(text, object_pairs_hook=_once if unique_keys else None)
    except JsonInputError:
        raise
    except json.JSONDecodeError as exc:
        raise JsonInputError(f"not valid JSON ({exc.msg} at line {exc.lineno}, column "
                             f"{exc.colno})") from None
    except (ValueError, RecursionError, OverflowError, TypeError) as exc:
        raise JsonInputError(f"not usable JSON ({str(exc)[:80]})") from None
