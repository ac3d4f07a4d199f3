"""One way to turn user-given values into config dataclass fields, by the fields' type hints.

Used by the scenario parser (TOML values: typed) and by ``ssl-robot --set FIELD=VALUE`` (text), so both
accept and refuse the same things with the same messages. Supported hints: ``bool``, ``int``, ``float``
(finite), ``str``, ``X | None``, ``tuple[X, ...]`` and ``tuple[X, Y, ...]``. Typed values must have the
field's type (TOML has no null: a value means "not None"). From text (``text=True``): ``true``/``false``
(also yes/no, 1/0), numbers as Python writes them, ``none`` for an optional field, comma lists for tuples
(an empty text is the empty tuple).
"""
from __future__ import annotations

import dataclasses
import math
import types
import typing
import warnings
from typing import Any

_NAMES = {int: "an integer", float: "a number", str: "a string", bool: "true/false"}
_TRUE, _FALSE = ("true", "yes", "1"), ("false", "no", "0")


def coerce(value: Any, hint: Any, what: str, text: bool = False) -> Any:
    """``value`` checked for a field of type ``hint`` (``text``: ``value`` is command-line text, converted
    first); ``what`` names the field in the ``ValueError`` raised otherwise."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        if len(inner) != 1:
            raise ValueError(f"{what}: unsupported field type {hint}")
        if text and value.strip().lower() == "none":
            return None
        return coerce(value, inner[0], what, text)
    if origin is tuple:
        if text:
            value = [s.strip() for s in value.split(",")] if value.strip() else []
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{what}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(v, args[0], what, text) for v in value)
        if len(value) != len(args):
            raise ValueError(f"{what}: expected a list of {len(args)} values, got {value!r}")
        return tuple(coerce(v, a, what, text) for v, a in zip(value, args))
    if hint in (int, float, str, bool):
        return check_scalar(value, hint, what, text)
    if dataclasses.is_dataclass(hint):
        raise ValueError(f"{what}: cannot be set from a value")
    return value


def check_scalar(value: Any, typ: type, what: str, text: bool = False) -> Any:
    """``value`` as a ``bool``/``int``/``float`` (finite)/``str``, else a ``ValueError`` naming ``what``."""
    if text and typ is not str:
        text = value.strip().lower()
        try:
            value = (True if text in _TRUE else False if text in _FALSE else _fail()) if typ is bool else typ(text)
        except ValueError:
            raise ValueError(f"{what}: expected {_NAMES[typ]}, got {value!r}") from None
    ok = (isinstance(value, bool) if typ is bool else
          isinstance(value, int) and not isinstance(value, bool) if typ is int else
          isinstance(value, (int, float)) and not isinstance(value, bool) if typ is float else
          isinstance(value, typ))
    if not ok:
        raise ValueError(f"{what}: expected {_NAMES.get(typ, typ.__name__)}, got {value!r} ({type(value).__name__})")
    if typ is float and not math.isfinite(value):
        raise ValueError(f"{what}: expected a finite number, got {value!r}")
    return float(value) if typ is float else value


def _fail():
    raise ValueError


def field_values(cls, values: dict[str, Any], what: str, text: bool = False, sep: str = ".") -> dict[str, Any]:
    """``values`` (field name -> value) checked against dataclass ``cls``'s init fields; unknown names are
    refused. Returns keyword arguments for ``cls``; names in errors read ``what`` + ``sep`` + field."""
    known = {f.name for f in dataclasses.fields(cls) if f.init}
    values = _without_retired(cls, values, what, sep)
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"{what}: unknown key(s) {unknown}; expected some of {sorted(known)}")
    hints = typing.get_type_hints(cls)
    return {k: coerce(v, hints[k], f"{what}{sep}{k}", text) for k, v in values.items()}


def _without_retired(cls, values: dict[str, Any], what: str, sep: str) -> dict[str, Any]:
    """``values`` without the fields ``cls`` retired (its ``RETIRED``: name -> why): a field whose value moved
    elsewhere (the text starts "MOVED:") is refused with where it went; one no decision read is ignored with a
    ``FutureWarning``, so that old scenario files still load."""
    retired = getattr(cls, "RETIRED", {})
    kept = {}
    for k, v in values.items():
        why = retired.get(k)
        if why is None:
            kept[k] = v
        elif why.startswith("MOVED:"):
            raise ValueError(f"{what}{sep}{k}: no longer a field of this section; {why[6:].strip()}")
        else:
            warnings.warn(f"{what}{sep}{k}: no longer a field ({why}); the value is ignored", FutureWarning,
                          stacklevel=3)
    return kept


def need(config: Any, ok: bool, name: str, expected: str) -> None:
    """A config check: unless ``ok``, a ``ValueError`` naming the class, the field, its value and ``expected``."""
    if not ok:
        raise ValueError(f"{type(config).__name__}.{name}={getattr(config, name)!r}: expected {expected}")


def in_section(message: str, cls: type, section: str) -> str:
    """A config error naming ``cls``'s field as ``Class.field`` re-worded as the user wrote it: ``section.field``
    (``section`` '': the bare field, e.g. a plain ``--set FIELD``); another message is prefixed ``section: ``."""
    name = f"{cls.__name__}."
    if name in message:
        return message.replace(name, f"{section}." if section else "", 1)
    return f"{section}: {message}" if section else message
