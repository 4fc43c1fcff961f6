"""Where values enter: one typed, bounded checker per kind of value.

Spec sections, CLI options and public constructors check what they are given with these
functions, so each kind of value (a duration, a sample rate, a seed, a path) is refused in one
way, with one message naming the field, the value (cut to ``errors.MAX_SHOWN`` characters) and
what is accepted. The bounds come from the physics and the machine: a sample rate the sensor
board could have, a step Brian2 can integrate, an amplitude whose products float64 still holds,
a recording that fits in memory.
"""
from __future__ import annotations

import math
import numbers
import os
import tomllib

from .errors import SpecError, shown

# Physics and machine bounds, each stated once.
MAX_RATE_HZ = 1e6            # a MHz ADC is far beyond any antenna board (the paper's: 1 kHz)
MIN_DT_MS = 1e-4             # 0.1 us: 50x finer than the finest step any study trades
MAX_AMPLITUDE = 1e6          # drives and levels; squares and sums of it stay far inside float64
# A seed reaches NumPy's legacy RandomState (through Brian2's ``seed`` and scikit-learn's
# ``random_state``), which takes 0 <= seed < 2**32; SeedSequence takes more, but one bound
# for every seed keeps a seed valid wherever it goes.
MAX_SEED = 2**32 - 1
SCENE_BYTES_PER_SAMPLE = 256  # a scene's arrays per sample while it is generated (~30 float64)
# The widest setting of any constructor in its own unit (rates, durations, currents, lengths
# are far below it): a setting beyond it is a typo, and products of two such numbers stay
# far inside float64. A count (iterations, epochs, samples) beyond MAX_COUNT would never finish.
MAX_MAGNITUDE = 1e9
MAX_COUNT = 2**32 - 1
# A nonzero number below the smallest normal float64 (a subnormal, e.g. 1e-320) underflows
# every product it enters and makes a reciprocal infinite: no setting is that small.
MIN_NORMAL = 2.2250738585072014e-308
NAME_MAX = 255               # bytes in one path component (Linux, macOS)
PATH_MAX = 4096              # bytes in a whole path (Linux)


def _real(value) -> bool:
    import numpy as np

    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def number(field: str, value, lo: float | None = None, hi: float | None = None, *,
           lo_open: bool = False, hi_open: bool = False, unit: str = "") -> float:
    """A finite real number in [lo, hi] (open ends where asked); returns it as a float."""
    lo_text = "" if lo is None else f"{'>' if lo_open else '>='} {lo:g}{unit}"
    hi_text = "" if hi is None else f"{'<' if hi_open else '<='} {hi:g}{unit}"
    accepted = "a finite number" + (f" {lo_text}" if lo_text else "") + (
        f"{' and' if lo_text else ''} {hi_text}" if hi_text else "")
    try:
        ok = _real(value) and math.isfinite(value)
    except (OverflowError, TypeError, ValueError):   # an int too large for a float
        ok = False
    if not ok:
        raise SpecError(field, value, accepted)
    x = float(value)
    if 0.0 < abs(x) < MIN_NORMAL:
        raise SpecError(field, value, f"{accepted} (0 or at least {MIN_NORMAL:.3g} in "
                                      "magnitude: a subnormal float underflows)")
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise SpecError(field, value, accepted)
    if hi is not None and (x > hi or (hi_open and x == hi)):
        raise SpecError(field, value, accepted)
    return x


def pair(field: str, value, lo: float = 0.0, strict: bool = False,
         unit: str = "") -> tuple[float, float]:
    """``[low, high]``: two finite numbers with ``lo <= low <= high`` (``low < high`` when
    ``strict``)."""
    accepted = (f"[low, high]{unit}: two finite numbers with {lo:g} <= low "
                f"{'<' if strict else '<='} high")
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SpecError(field, value, accepted)
    low, high = (number(f"{field}.{i}", v) for i, v in enumerate(value))
    if low < lo or high < low or (strict and high == low):
        raise SpecError(field, value, accepted)
    return low, high


def integer(field: str, value, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (not true/false, not 2.0) in [lo, hi]."""
    import numpy as np

    accepted = "an integer" + (f" >= {lo}" if lo is not None else "") + (
        f"{' and' if lo is not None else ''} <= {hi}" if hi is not None else "")
    if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
        raise SpecError(field, value, accepted)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise SpecError(field, value, accepted)
    return int(value)


def seed(field: str, value):
    """A random seed: an integer in [0, MAX_SEED], or a NumPy ``SeedSequence`` (how a study
    hands each of its parts its own stream); returned as given."""
    import numpy as np

    if isinstance(value, np.random.SeedSequence):
        return value
    accepted = f"an integer >= 0 and <= {MAX_SEED}, or a numpy SeedSequence"
    if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) \
            or not 0 <= value <= MAX_SEED:
        raise SpecError(field, value, accepted)
    return int(value)


def choice(field: str, value, options) -> str:
    """One of ``options`` (strings)."""
    if not isinstance(value, str) or value not in options:
        raise SpecError(field, value, f"one of {', '.join(repr(o) for o in options)}")
    return value


def rate_hz(field: str, value) -> float:
    """A sample rate in (0, MAX_RATE_HZ] Hz."""
    return number(field, value, 0.0, MAX_RATE_HZ, lo_open=True, unit=" Hz")


def dt_ms(field: str, value, hi: float = 1.0) -> float:
    """An integration step in [MIN_DT_MS, hi] ms."""
    return number(field, value, MIN_DT_MS, hi, unit=" ms")


def amplitude(field: str, value, lo: float = -MAX_AMPLITUDE) -> float:
    """An amplitude or level within +-MAX_AMPLITUDE (``lo`` = 0 for magnitudes)."""
    return number(field, value, lo, MAX_AMPLITUDE)


def n_samples(field: str, duration_s, rate: float, bytes_per_sample: int = 16,
              budget: int | None = None) -> int:
    """Samples of a recording ``duration_s`` long at ``rate`` Hz, refused when they (at
    ``bytes_per_sample`` while being made) would not fit in a quarter of the memory available."""
    duration = number(field, duration_s, 0.0, lo_open=True, unit=" s")
    if budget is None:
        budget = memory_budget_bytes()
    most = max(1, budget // bytes_per_sample)
    n = duration * rate
    if not n < most:
        raise SpecError(field, duration_s,
                        f"a duration > 0 s and at most {most / rate:.4g} s at {rate:g} Hz "
                        f"({n * bytes_per_sample / 2**30:.3g} GiB needed, "
                        f"{budget / 2**30:.3g} GiB allowed: a quarter of the memory available)")
    return int(round(n))


def out_path(field: str, value) -> str:
    """A path the file system can hold: text that encodes as UTF-8 (no lone surrogates from
    undecodable bytes), components of at most NAME_MAX bytes, at most PATH_MAX bytes in all."""
    if not isinstance(value, (str, os.PathLike)):
        raise SpecError(field, value, "a path")
    text = os.fspath(value)
    try:
        encoded = text.encode("utf-8")
    except UnicodeEncodeError:
        raise SpecError(field, text, "a path in UTF-8 text (this one holds bytes that "
                                     "are not UTF-8)") from None
    if "\x00" in text or not text:
        raise SpecError(field, text, "a non-empty path without NUL characters")
    longest = max(len(part.encode("utf-8")) for part in text.split(os.sep))
    if longest > NAME_MAX or len(encoded) > PATH_MAX:
        raise SpecError(field, text, f"a path whose names are at most {NAME_MAX} bytes each "
                                     f"and at most {PATH_MAX} bytes in all")
    return text


def instance(field: str, value, cls, what: str) -> None:
    """``value`` is a ``cls`` (e.g. a list entry that must be a Contact, not a tuple)."""
    if not isinstance(value, cls):
        raise SpecError(field, value, what)


# Command-line options: argparse turns an ArgumentTypeError into one line and exit status 2.
MAX_SECONDS = 365 * 86400.0  # a timeout, a hold or a recording's length: a year at most
BAUDRATES = (50, 12_000_000)  # what serial ports and USB bridges (FTDI: 12 Mbaud) can run


def option(checker, text: bool = False):
    """An argparse ``type`` from a checker: ``type=option(seconds)``; the option's message is
    the checker's (field, value, what is accepted), cut as every SpecError is. The option's
    text is read as a TOML value (``inf``, ``1e9``, ``2``) unless ``text`` (paths)."""
    import argparse

    def parse(given: str):
        try:
            return checker("value", given if text else parse_value(given))
        except SpecError as exc:
            raise argparse.ArgumentTypeError(f"{shown(given)} is not accepted: "
                                             f"{exc.accepted}") from None
    parse.__name__ = checker.__name__
    return parse


def seconds(field: str, value, lo: float = 0.0) -> float:
    """A time in [lo, MAX_SECONDS] s (a timeout, a hold, a recording's length)."""
    return number(field, value, lo, MAX_SECONDS, unit=" s")


def positive_seconds(field: str, value) -> float:
    return number(field, value, 0.0, MAX_SECONDS, lo_open=True, unit=" s")


def baudrate(field: str, value) -> int:
    return integer(field, value, *BAUDRATES)


def positive_integer(field: str, value) -> int:
    return integer(field, value, 1)


MAX_DEPTH = 32               # tables and lists nested in a spec value (its deepest has 4)


def parse_value(text: str, field: str = "value"):
    """A value typed on the command line, read as TOML (``48``, ``[5, 40]``, ``inf``); text
    that is not TOML stays the text it is. A value TOML reads but Python cannot hold (an
    integer of thousands of digits, lists nested past the interpreter's limit) is refused."""
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except (ValueError, RecursionError, MemoryError) as exc:
        raise SpecError(field, text, beyond_limits(exc)) from None
    return nested(field, value)


def beyond_limits(exc: BaseException) -> str:
    """What is accepted, for a value Python could not read (``exc``)."""
    if isinstance(exc, RecursionError):
        return f"tables and lists nested at most {MAX_DEPTH} deep"
    return (f"a number of at most {_max_digits()} digits (and values that fit in memory)"
            if isinstance(exc, ValueError) else "a value that fits in memory")


def _max_digits() -> int:
    import sys

    return sys.get_int_max_str_digits() or 4300


def nested(field: str, value, depth: int = MAX_DEPTH):
    """``value`` (a spec value read from TOML) refused when its tables and lists are nested
    more than ``depth`` deep, naming the dotted key where it goes too deep. Iterative: a value
    nested past the interpreter's recursion limit is refused, not a RecursionError."""
    stack = [(field, value, 0)]
    while stack:
        where, item, level = stack.pop()
        if level > depth:
            raise SpecError(where, "(nested deeper)", f"tables and lists nested at most "
                                                      f"{depth} deep")
        if isinstance(item, dict):
            stack += [(f"{where}.{k}", v, level + 1) for k, v in item.items()]
        elif isinstance(item, list):
            stack += [(f"{where}.{i}", v, level + 1) for i, v in enumerate(item)]
    return value


def memory_budget_bytes() -> int:
    """A quarter of the memory available now: what a run or a sweep may hold at once."""
    try:
        import psutil
        available = psutil.virtual_memory().available
    except ImportError:  # psutil comes with distributed; this is a fallback
        available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(available) // 4


# -- checks read from a class's declaration ------------------------------------------------
# A constructor's annotations are its declaration: the spec checks read them (``spec.
# check_type``) and so does ``declared`` below, with one wording (``describe_type``) for what
# each accepts. ``declared`` is strict where the spec check is lenient: a constructor is
# handed Python values, not TOML, so a word is not a number there.

def describe_type(tp, none: bool = True) -> str:
    """What a value of the annotation ``tp`` is, in the words of a refusal (``none``: whether
    an optional field says it may be none; a TOML spec has no none to give)."""
    import types
    import typing

    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is bool:
        return "true or false"
    if tp is int:
        return "an integer (not true/false)"
    if tp is float:
        return "a number (not true/false)"
    if tp is str:
        return "a string"
    if origin is tuple and args and args[-1] is not Ellipsis:
        if all(a in (int, float) for a in args):
            return f"a list of {len(args)} numbers, e.g. {list(range(7, 7 + len(args)))}"
        return f"a list of {len(args)} ({', '.join(describe_type(a, none) for a in args)})"
    if origin in (tuple, list) or tp in (tuple, list) or _is_sequence(origin or tp):
        return f"a list of {describe_type(args[0], none) if args else 'values'}"
    if origin is dict or tp is dict:
        return "a table"
    if origin in (typing.Union, types.UnionType):
        return " or ".join("none" if a is type(None) else describe_type(a, none)
                           for a in args if none or a is not type(None))
    return getattr(tp, "__name__", str(tp))


def _is_sequence(tp) -> bool:
    import collections.abc

    return tp is collections.abc.Sequence


_DECLARED: dict = {}


def declared_types(target) -> dict:
    """The annotations of a dataclass's fields (those ``__init__`` takes), a class's
    ``__init__`` or a function's parameters, resolved ({} where they cannot be); cached."""
    import dataclasses
    import typing

    if target not in _DECLARED:
        plain_class = isinstance(target, type) and not dataclasses.is_dataclass(target)
        try:
            hints = typing.get_type_hints(target.__init__ if plain_class else target)
        except Exception:   # annotations that cannot be resolved: no type check, not a crash
            hints = {}
        hints.pop("return", None)
        if dataclasses.is_dataclass(target):
            init = {f.name for f in dataclasses.fields(target) if f.init}
            hints = {k: v for k, v in hints.items() if k in init}
        _DECLARED[target] = hints
    return dict(_DECLARED[target])


def declared(obj, **values) -> None:
    """Refuse a field of ``obj`` whose value is not of its declared type, or is a number no
    setting takes (NaN, inf, a subnormal, beyond MAX_MAGNITUDE, a count beyond MAX_COUNT).

    A dataclass is checked on its fields (``declared(self)`` first in ``__post_init__``);
    another class on the ``values`` its ``__init__`` was given (``declared(self, rate_hz=
    rate_hz)``). Ranges of one field (a rate > 0, a probability <= 1) are its class's own
    checks, after this one."""
    cls = type(obj)
    checks = _CHECKS.get(cls)
    if checks is None:                  # each class's checks are made once, from its types
        checks = {name: (tp, _check_for(tp)) for name, tp in declared_types(cls).items()}
        checks = _CHECKS[cls] = {k: v for k, v in checks.items() if v[1] is not None}
    if not values and hasattr(cls, "__dataclass_fields__"):
        values = {name: getattr(obj, name) for name in checks}
    for name, value in values.items():
        if name in checks:
            tp, check = checks[name]
            if not check(name, value):
                raise SpecError(name, value, describe_type(tp))


_CHECKS: dict = {}


def _check_for(tp):
    """A check ``(field, value) -> bool`` for the annotation ``tp``: False for a value of
    another type, a SpecError for one of this type out of every bound, True otherwise; None
    where the annotation says nothing to check (arrays, protocols, callables)."""
    import types
    import typing

    import numpy as np

    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is typing.Any or tp is object:
        return None
    if tp is bool:
        return lambda field, value: isinstance(value, (bool, np.bool_))
    if tp is float:
        def real(field, value) -> bool:
            if type(value) is float and (MIN_NORMAL <= abs(value) <= MAX_MAGNITUDE
                                         or value == 0.0):
                return True             # the common case, at once
            if not _real(value):
                return False
            number(field, value, -MAX_MAGNITUDE, MAX_MAGNITUDE)
            return True
        return real
    if tp is int:
        def count(field, value) -> bool:
            if type(value) is int and -MAX_COUNT <= value <= MAX_COUNT:
                return True
            if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
                return False
            integer(field, value, -MAX_COUNT, MAX_COUNT)
            return True
        return count
    if tp is str:
        return lambda field, value: isinstance(value, str)
    if origin in (typing.Union, types.UnionType):
        optional = type(None) in args
        kinds = [_check_for(a) for a in args if a is not type(None)]
        if any(k is None for k in kinds):
            return (lambda field, value: True) if optional else None

        def either(field, value) -> bool:
            if value is None:
                return optional
            errors = []
            for kind in kinds:              # the first kind the value is of decides
                try:
                    if kind(field, value):
                        return True
                except SpecError as exc:
                    errors.append(exc)
            if errors:
                raise errors[0]
            return False
        return either
    container = origin or tp
    if container in (tuple, list) or _is_sequence(container):
        if origin is tuple and args and args[-1] is not Ellipsis:
            entries = [_check_for(a) for a in args]

            def fixed(field, value) -> bool:
                if not isinstance(value, (list, tuple, np.ndarray)) or np.ndim(value) != 1 \
                        or len(value) != len(entries):
                    return False
                return all(check is None or check(f"{field}.{i}", v)
                           for i, (v, check) in enumerate(zip(value, entries)))
            return fixed
        entry = _check_for(args[0]) if args else None
        entry_text = describe_type(args[0]) if args else ""

        def listed(field, value) -> bool:
            if not isinstance(value, (list, tuple, np.ndarray)) or np.ndim(value) == 0:
                return False
            for i, item in enumerate(value):
                if entry is not None:
                    if not entry(f"{field}.{i}", item):
                        raise SpecError(f"{field}.{i}", item, entry_text)
                elif _real(item):           # an undeclared entry that is a number is sane
                    number(f"{field}.{i}", item, -MAX_MAGNITUDE, MAX_MAGNITUDE)
                elif isinstance(item, complex):
                    raise SpecError(f"{field}.{i}", item, "a real number, a string or a table")
            return True
        return listed
    if container is dict:
        return lambda field, value: isinstance(value, dict)
    if isinstance(tp, type) and tp.__module__.startswith("snn_antenna"):
        return lambda field, value: isinstance(value, tp)   # one of the package's own
    return None
