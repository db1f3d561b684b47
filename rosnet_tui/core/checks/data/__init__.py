"""What each check reports in its ``data``: declared per check id, the ``check --json`` contract.

Checks produce plain dicts (their JSON form is unchanged); the declarations below say which keys
each check id may carry and what they hold. Consumers (the advisor's rules, the UI, the report)
read the data through :func:`view`, which refuses a key that no check declares: a renamed key
fails the ordinary test run instead of silently switching a rule off. Producers are held to the
same declarations by :func:`undeclared` (the check runner calls it in strict mode, which the
test suite turns on).

The declarations live by step (isp_router, linux, ros, security, relay; shared kinds in kinds); this
module holds the table of them all (DATA) and the mechanism. Standard library only: the advisor
depends on it, not on any check module.
"""

from __future__ import annotations

import os
import types
import typing
from collections.abc import Iterator, Mapping
from typing import Any

from rosnet_tui.core.checks.data import isp_router, linux, relay, ros, security

STRICT_ENV = "ROSNET_TUI_STRICT_DATA"


def strict() -> bool:
    """True when undeclared keys must raise (the test suite sets ROSNET_TUI_STRICT_DATA=1)."""
    return os.environ.get(STRICT_ENV, "") not in ("", "0")

# --------------------------------------------------------------------------- declarations
# One TypedDict per check id (total=False: a check sets the keys its verdict has evidence for; a
# skip may carry only a few). Nested shapes (per-peer dicts, port rows) are TypedDicts too, which
# :func:`view` and :func:`undeclared` follow. The comment on each key is its documentation;
# docs/COMMANDS.md's table of the checks lists the top-level keys. Values are JSON (dict keys: str).

DATA: dict[str, type] = {**isp_router.DATA, **linux.DATA, **ros.DATA, **security.DATA,
                         **relay.DATA}


# --------------------------------------------------------------------------- the mechanism
class UndeclaredKeyError(Exception):
    """A consumer read, or a producer wrote, a key that the check's declaration does not have.

    Deliberately not a KeyError: ``Mapping.get`` would swallow that and return the default.
    """


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(td: type) -> dict[str, Any]:
    if td not in _HINTS:
        _HINTS[td] = typing.get_type_hints(td)
    return _HINTS[td]


def declared_keys(check_id: str) -> frozenset[str]:
    """The keys *check_id* may report (empty for an unknown id)."""
    td = DATA.get(check_id)
    return frozenset(_hints(td)) if td is not None else frozenset()


def _strip(tp: Any) -> Any:
    """``X | None`` -> X; NotRequired/Required[X] -> X."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return _strip(args[0])
    return tp


def _wrap(value: Any, tp: Any, where: str) -> Any:
    """Wrap nested dicts whose declared type is a TypedDict (directly, in a list, as dict values)."""
    tp = _strip(tp)
    if typing.is_typeddict(tp) and isinstance(value, dict):
        return CheckData(where, value, tp)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (list, tuple) and args and isinstance(value, list):
        inner = _strip(args[0])
        if typing.is_typeddict(inner):
            return [CheckData(f"{where}[]", v, inner) if isinstance(v, dict) else v
                    for v in value]
    if origin is dict and len(args) == 2 and isinstance(value, dict):
        inner = _strip(args[1])
        if typing.is_typeddict(inner):
            return {k: CheckData(f"{where}[{k!r}]", v, inner) if isinstance(v, dict) else v
                    for k, v in value.items()}
    return value


class CheckData(Mapping[str, Any]):
    """A read-only view of one check's data that refuses keys its declaration lacks."""

    __slots__ = ("_where", "_data", "_td")

    def __init__(self, where: str, data: Mapping[str, Any] | None, td: type | None) -> None:
        self._where = where
        self._data = data if isinstance(data, Mapping) else {}
        self._td = td

    def _declared(self, key: str) -> Any:
        if self._td is None:
            raise UndeclaredKeyError(f"{self._where}: no data is declared for this check "
                                     f"(reading {key!r}); add it to rosnet_tui/core/checks/data/")
        hints = _hints(self._td)
        if key not in hints:
            raise UndeclaredKeyError(f"{self._where}: {key!r} is not a declared key "
                                     f"({self._td.__name__}); declared: {', '.join(sorted(hints))}")
        return hints[key]

    def __getitem__(self, key: str) -> Any:
        tp = self._declared(key)
        return _wrap(self._data[key], tp, f"{self._where}.{key}")

    def get(self, key: str, default: Any = None) -> Any:
        tp = self._declared(key)
        if key not in self._data:
            return default
        return _wrap(self._data[key], tp, f"{self._where}.{key}")

    def __contains__(self, key: object) -> bool:
        if isinstance(key, str):
            self._declared(key)
        return key in self._data

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __bool__(self) -> bool:
        return bool(self._data)

    def __repr__(self) -> str:
        return f"CheckData({self._where!r}, {dict(self._data)!r})"

    def raw(self) -> dict[str, Any]:
        """The plain dict underneath (for JSON output)."""
        return dict(self._data)


def view(check_id: str, data: Mapping[str, Any] | None) -> CheckData:
    """*data* of *check_id* as a declared, read-only view."""
    return CheckData(check_id, data, DATA.get(check_id))


def undeclared(check_id: str, data: Mapping[str, Any] | None) -> list[str]:
    """The keys (dotted paths for nested ones) in *data* that *check_id* does not declare."""
    td = DATA.get(check_id)
    if not data:
        return []
    if td is None:
        return [f"{check_id}: (no declaration)"]
    out: list[str] = []
    _collect(data, td, check_id, out)
    return out


def _collect(data: Mapping[str, Any], td: type, where: str, out: list[str]) -> None:
    hints = _hints(td)
    for key, value in data.items():
        if key not in hints:
            out.append(f"{where}.{key}")
            continue
        tp = _strip(hints[key])
        if typing.is_typeddict(tp) and isinstance(value, Mapping):
            _collect(value, tp, f"{where}.{key}", out)
            continue
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin in (list, tuple) and args and typing.is_typeddict(_strip(args[0])):
            for v in value if isinstance(value, list) else []:
                if isinstance(v, Mapping):
                    _collect(v, _strip(args[0]), f"{where}.{key}[]", out)
        elif origin is dict and len(args) == 2 and typing.is_typeddict(_strip(args[1])):
            for k, v in (value.items() if isinstance(value, Mapping) else []):
                if isinstance(v, Mapping):
                    _collect(v, _strip(args[1]), f"{where}.{key}[{k!r}]", out)
