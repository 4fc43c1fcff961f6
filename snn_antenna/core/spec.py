"""Declarative specs: TOML files that name a study, its network, stimulus and settings.

A study spec (``studies/*.toml``) may include a network, stimulus or chosen-bank spec by path
(``network = "../networks/resonator_array.toml"``, resolved relative to the including file);
the included table takes that key's place. ``--set key.sub=value`` overrides any field after
includes (values are read as TOML, so ``--set network.band_hz=[5,40]`` works; a bare word is
a string). A ``[quick]`` table holds the overrides that ``--quick`` applies: the small profile
for tests and first looks. Every key is checked against what the study accepts before any
work starts, and an unknown key is refused with the list of known ones.
"""
from __future__ import annotations

import copy
import dataclasses
import inspect
import tomllib
import types
import typing
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from collections.abc import Iterable

from . import calibration
from .bounds import beyond_limits, declared_types, describe_type, nested, out_path, parse_value
from .bounds import seed as checked_seed
from .errors import NumericalInstabilityError, SpecError, shown

INCLUDABLE = ("network", "stimulus", "chosen_bank")


def load(path: str | Path, overrides: Iterable[str] = (), quick: bool = False) -> dict:
    """Read a spec, resolve includes, apply the quick profile, put the calibrated constants
    it names in place (``core.calibration``) and apply ``--set`` overrides."""
    path = Path(out_path("spec", path))
    if not path.is_file():
        raise SpecError("spec", str(path), "the path of an existing TOML spec file")
    spec = _read(path)
    for key in INCLUDABLE:
        if isinstance(spec.get(key), str):
            included = (path.parent / out_path(key, spec[key])).resolve()
            if not included.is_file():
                raise SpecError(key, spec[key], f"a TOML file path relative to {path.parent}")
            spec[key] = _read(included, key)
    quick_overrides = spec.pop("quick", {})
    if quick:
        for dotted, value in _flatten(quick_overrides):
            set_field(spec, dotted, value)
    spec = calibration.resolve(spec)        # "calibrated:NAME": the table's value, which
    for item in overrides:                  # --set may override with a number
        apply_override(spec, item)
    spec.setdefault("seed", 0)
    return spec


def _read(path: Path, field: str = "spec") -> dict:
    """A TOML file's table, refused by ``field``'s name when it is not TOML."""
    try:
        with open(path, "rb") as f:
            table = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(field, str(path), f"valid TOML ({exc})") from None
    except UnicodeDecodeError:              # tomllib reads bytes but wants UTF-8 text
        raise SpecError(field, str(path), "a TOML file in UTF-8 text (this one is binary "
                                           "or in another encoding)") from None
    except (ValueError, RecursionError, MemoryError) as exc:   # TOML Python cannot hold
        raise SpecError(field, str(path), f"a TOML file with {beyond_limits(exc)}") from None
    for key, value in table.items():
        nested(key, value)
    return table


def _flatten(table: dict, prefix: str = ""):
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


_MISSING = object()
RANGE_KEYS = {"start", "stop", "num", "scale"}   # a sweep axis as a range (engine.grid)


def apply_override(spec: dict, item: str) -> None:
    """One ``--set key=value``: the value read as TOML (``bounds.parse_value``), of the kind
    the spec has there (``same_kind``), set in place (``set_field``)."""
    if "=" not in item:
        raise SpecError("--set", item, "key=value, e.g. network.n_neurons=48")
    dotted, text = item.split("=", 1)
    dotted = dotted.strip()
    value = parse_value(text.strip(), dotted or "--set")
    before = get_field(spec, dotted, _MISSING) if dotted else _MISSING
    if before is not _MISSING:
        same_kind(dotted, before, value)
    set_field(spec, dotted, value)


def _kind(value) -> str:
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a finite number (not true/false, not a text)"
    if isinstance(value, str):
        return "a text"
    if isinstance(value, list) or (isinstance(value, dict) and value
                                   and set(value) <= RANGE_KEYS):
        return "a list"                 # a range table stands for its list of values
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def same_kind(dotted: str, before, value) -> None:
    """A ``--set`` value keeps the kind of value the spec has there: a number stays a number,
    a list of numbers a list of numbers, a table a table (its known keys checked the same
    way). The field's own range and rules are its study's checks; this one stops a text or a
    table from reaching code that reads a number."""
    accepted = f"{_kind(before)}, as the spec's value there ({shown(before)}) is"
    if _kind(value) != _kind(before):
        raise SpecError(dotted, value, accepted)
    if isinstance(before, list) and before and isinstance(value, list):
        kinds = {_kind(v) for v in before}
        if len(kinds) == 1:
            kind = kinds.pop()
            for i, item in enumerate(value):
                if _kind(item) != kind:
                    raise SpecError(f"{dotted}.{i}", item, f"{kind}, as every entry of the "
                                                          f"spec's {dotted} is")
    if isinstance(before, dict) and isinstance(value, dict):
        for key, item in value.items():
            if key in before:
                same_kind(f"{dotted}.{key}", before[key], item)


def set_field(spec: dict, dotted: str, value: Any) -> None:
    """Set ``dotted`` (``table.key``, ``list.INDEX.key``) to ``value``; a missing table is
    created, a list index must name an existing entry (``contacts.0``, not ``contacts.5`` of a
    one-entry list, ``contacts.x`` or ``contacts.-1``)."""
    parts = dotted.split(".")
    if not dotted or any(not p.strip() for p in parts):
        raise SpecError("--set", dotted, "a dotted key such as network.n_neurons")
    *parents, last = parts
    node = spec
    for i, key in enumerate(parents):
        where = ".".join(parts[:i])
        if isinstance(node, list):
            node = node[_list_index(node, key, where, ".".join(parts[:i + 1]))]
        else:
            node = node.setdefault(key, {})
        if not isinstance(node, (dict, list)):
            raise SpecError(".".join(parts[:i + 1]), node, "a table to set fields in")
    if isinstance(node, list):
        node[_list_index(node, last, ".".join(parents), dotted)] = value
    else:
        node[last] = value


def get_field(spec: dict, dotted: str, default=None):
    """The value at ``dotted`` (``table.key``), or ``default`` where a table or key is missing."""
    node = spec
    for key in dotted.split("."):
        if not isinstance(node, dict) or key not in node:
            return default
        node = node[key]
    return node


def _list_index(items: list, key: str, where: str, dotted: str) -> int:
    """The entry of list ``where`` that ``key`` names, or a SpecError naming the user's key."""
    if not (key.isascii() and key.isdigit()) or int(key) >= len(items):
        accepted = (f"an index in 0..{len(items) - 1} of the {len(items)} entr"
                    f"{'y' if len(items) == 1 else 'ies'} of {where} (to add an entry, "
                    f"write it in the spec file)" if items else f"nothing: {where} is empty")
        raise SpecError(dotted, key, accepted)
    return int(key)


def accepted_keys(target) -> dict[str, Any]:
    """Keyword names (with defaults) that a dataclass or callable accepts."""
    if dataclasses.is_dataclass(target):
        return {f.name: (f.default if f.default is not dataclasses.MISSING else None)
                for f in dataclasses.fields(target)}
    params = inspect.signature(target).parameters
    return {name: (p.default if p.default is not inspect.Parameter.empty else None)
            for name, p in params.items() if p.kind is p.KEYWORD_ONLY or
            p.kind is p.POSITIONAL_OR_KEYWORD}


def check_section(spec: dict, section: str, target, exclude: Iterable[str] = (),
                  extra: Iterable[str] = ()) -> dict:
    """Refuse keys of ``spec[section]`` that ``target`` does not take, and values whose type
    is not the one ``target`` declares for them (see :func:`check_type`); return the table."""
    table = spec.get(section, {})
    if not isinstance(table, dict):
        raise SpecError(section, table, "a table of settings")
    allowed = (set(accepted_keys(target)) - set(exclude)) | set(extra)
    for key in table:
        if key not in allowed:
            raise SpecError(f"{section}.{key}", table[key],
                            f"a known key of [{section}]: {', '.join(sorted(allowed))}")
    hints = declared_types(target)
    for key, value in table.items():
        if key in hints:
            check_type(f"{section}.{key}", value, hints[key])
    return table


def _matches(value, tp) -> bool:
    """Whether ``value`` is plainly not of type ``tp``. Deliberately lenient: a target may
    accept more than it declares (a word such as "never" for a float field), so only the
    mistakes no target means are refused: true/false for a number, a number for true/false,
    a list of the wrong length for a fixed-length pair, a table or list for a number."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is bool:
        return isinstance(value, bool)
    if tp in (int, float):
        return not isinstance(value, (bool, list, tuple, dict))
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, a) for a in args if a is not type(None))
    if origin is tuple and args and args[-1] is not Ellipsis and isinstance(value, (list, tuple)):
        return len(value) == len(args) and all(_matches(v, a) for v, a in zip(value, args))
    if origin in (tuple, list) and args and isinstance(value, (list, tuple)):
        return all(_matches(v, args[0]) for v in value)
    return True


def check_type(field: str, value, tp) -> None:
    """Refuse ``value`` unless it has the declared type ``tp``: TOML ``true`` is not the
    integer 1, a ``[low, high]`` pair has two entries, a number is not a string."""
    if not _matches(value, tp):
        raise SpecError(field, value, describe_type(tp, none=False))


def check_top_level(spec: dict, sections: Iterable[str]) -> None:
    allowed = set(sections) | {"study", "seed", "description"}
    for key in spec:
        if key not in allowed:
            raise SpecError(key, spec[key],
                            f"a known top-level key of this study: {', '.join(sorted(allowed))}")
    checked_seed("seed", spec.get("seed", 0))


@contextmanager
def section(name: str):
    """Prefix the field of any SpecError raised inside with the spec section's name; any other
    error a value of the section caused while its parts were built names the section."""
    try:
        yield
    except SpecError as exc:
        if exc.field == name or exc.field.startswith(f"{name}."):
            raise
        raise SpecError(f"{name}.{exc.field}", exc.value, exc.accepted) from None
    except TypeError as exc:  # a wrong type that slipped past key checks
        raise SpecError(name, "a value of the wrong type", str(exc)) from None
    except NumericalInstabilityError:
        raise
    except (ValueError, ArithmeticError, IndexError, KeyError) as exc:
        # a value that slipped past the section's checks: building the parts needs nothing
        # but the spec, so what failed there is the spec's (and the message says what)
        raise SpecError(name, "one of its values",
                        f"values its parts can be built from ({type(exc).__name__}: "
                        f"{str(exc)[:200]})") from None


def resolved(spec: dict) -> dict:
    return copy.deepcopy(spec)
