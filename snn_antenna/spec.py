"""Declarative specs: TOML files that name a study, its network, stimulus and settings.

A study spec (``studies/*.toml``) may include a network or stimulus spec by path
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
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable

from .errors import SpecError

INCLUDABLE = ("network", "stimulus")


def load(path: str | Path, overrides: Iterable[str] = (), quick: bool = False) -> dict:
    """Read a spec, resolve includes, apply the quick profile and ``--set`` overrides."""
    path = Path(path)
    if not path.is_file():
        raise SpecError("spec", str(path), "the path of an existing TOML spec file")
    spec = _read(path)
    for key in INCLUDABLE:
        if isinstance(spec.get(key), str):
            included = (path.parent / spec[key]).resolve()
            if not included.is_file():
                raise SpecError(key, spec[key], f"a TOML file path relative to {path.parent}")
            spec[key] = _read(included)
    quick_overrides = spec.pop("quick", {})
    if quick:
        for dotted, value in _flatten(quick_overrides):
            set_field(spec, dotted, value)
    for item in overrides:
        if "=" not in item:
            raise SpecError("--set", item, "key=value, e.g. network.n_neurons=48")
        dotted, text = item.split("=", 1)
        set_field(spec, dotted.strip(), parse_value(text.strip()))
    spec.setdefault("seed", 0)
    return spec


def _read(path: Path) -> dict:
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError("spec", str(path), f"valid TOML ({exc})") from None


def _flatten(table: dict, prefix: str = ""):
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_field(spec: dict, dotted: str, value: Any) -> None:
    *parents, last = dotted.split(".")
    node = spec
    for i, key in enumerate(parents):
        if key.isdigit() and isinstance(node, list):
            node = node[int(key)]
            continue
        node = node.setdefault(key, {})
        if not isinstance(node, (dict, list)):
            raise SpecError(".".join(parents[:i + 1]), node, "a table to set fields in")
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


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
    """Refuse keys of ``spec[section]`` that ``target`` does not take; return the table."""
    table = spec.get(section, {})
    if not isinstance(table, dict):
        raise SpecError(section, table, "a table of settings")
    allowed = (set(accepted_keys(target)) - set(exclude)) | set(extra)
    for key in table:
        if key not in allowed:
            raise SpecError(f"{section}.{key}", table[key],
                            f"a known key of [{section}]: {', '.join(sorted(allowed))}")
    return table


def check_top_level(spec: dict, sections: Iterable[str]) -> None:
    allowed = set(sections) | {"study", "seed", "description"}
    for key in spec:
        if key not in allowed:
            raise SpecError(key, spec[key],
                            f"a known top-level key of this study: {', '.join(sorted(allowed))}")
    seed = spec.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise SpecError("seed", seed, "an integer >= 0")


@contextmanager
def section(name: str):
    """Prefix the field of any SpecError raised inside with the spec section's name."""
    try:
        yield
    except SpecError as exc:
        if exc.field.startswith(f"{name}."):
            raise
        raise SpecError(f"{name}.{exc.field}", exc.value, exc.accepted) from None
    except TypeError as exc:  # a wrong type that slipped past key checks
        raise SpecError(name, "a value of the wrong type", str(exc)) from None


def resolved(spec: dict) -> dict:
    return copy.deepcopy(spec)
