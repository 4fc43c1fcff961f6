"""Commands as declarations: each subcommand declares its options once (type, bounds, help),
and the command-line parser, the options object and the refusals are made from that.

A :class:`Command` names a subcommand, its help, the function that runs it and its
:class:`Option` declarations. ``snn_antenna.cli`` mounts every declared command on one parser
(:func:`build_parser`); argparse only splits the words and reads TOML-typed values
(``bounds.parse_value``). The values are checked when the command's options object is made
(``command.Options(...)``), from the command line and from Python alike: an option's checker
(a function of :mod:`snn_antenna.core.bounds`, ``checker(field, value) -> value``) refuses a
value with one line naming the option, the value and what is accepted::

    --duration = -1 is not accepted: a finite number > 0 s and <= 3.1536e+07 s

so a bound is written once and refused in one way, whichever door the value came in by.
"""
from __future__ import annotations

import argparse
import dataclasses
import difflib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from . import bounds
from .errors import SpecError

# What an option is on the command line.
VALUE, SWITCH, LIST, POSITIONAL, POSITIONALS = (
    "value", "switch", "list", "positional", "positionals")


@dataclass(frozen=True)
class Option:
    """One option of a command, declared once.

    ``name`` is the options object's field (``--name-with-dashes`` on the command line);
    ``check(field, value) -> value`` bounds it (None: text, taken as given); ``text``: the
    typed words are the value (paths, addresses, URLs), not read as TOML; ``kind``: a
    ``value``, an on/off ``switch``, a repeatable ``list`` (``nargs`` words each time), a
    ``positional`` word or ``positionals`` (any number)."""
    name: str
    help: str
    check: Callable[[str, Any], Any] | None = None
    default: Any = None
    kind: str = VALUE
    text: bool = False
    required: bool = False
    choices: tuple[str, ...] = ()
    metavar: str | tuple[str, ...] | None = None
    nargs: int | None = None

    @property
    def flag(self) -> str:
        return self.name if self.kind in (POSITIONAL, POSITIONALS) else \
            "--" + self.name.replace("_", "-")

    def checked(self, value):
        """``value`` as the option holds it; a SpecError naming the option otherwise."""
        if self.kind == SWITCH:
            if not isinstance(value, bool):
                raise SpecError(self.flag, value, "true or false")
            return value
        if self.kind in (LIST, POSITIONALS):
            if not isinstance(value, (list, tuple)):
                raise SpecError(self.flag, value, "a list")
            return [self._one(item) for item in value]
        if value is None and not self.required and self.default is None:
            return None
        return self._one(value)

    def _one(self, value):
        if self.choices:
            return bounds.choice(self.flag, value, self.choices)
        if self.nargs is not None:
            if not isinstance(value, (list, tuple)) or len(value) != self.nargs \
                    or not all(isinstance(v, str) for v in value):
                raise SpecError(self.flag, value, f"{self.nargs} words")
            return tuple(value)
        if self.check is not None:
            return self.check(self.flag, value)
        if not isinstance(value, str):
            raise SpecError(self.flag, value, "text")
        return value

    def typed(self, words):
        """What the command line gave, as a value: TOML-read unless ``text``."""
        if self.text or self.check is None:
            return words
        if isinstance(words, list):
            return [self.typed(w) for w in words]
        return bounds.parse_value(words, self.flag) if isinstance(words, str) else words

    def add_to(self, parser) -> None:
        kwargs: dict[str, Any] = {"help": self.help}
        if self.metavar is not None:
            kwargs["metavar"] = self.metavar
        elif self.choices:
            kwargs["metavar"] = "{" + ",".join(self.choices) + "}"
        if self.kind == POSITIONAL:
            parser.add_argument(self.name, **kwargs)
        elif self.kind == POSITIONALS:
            parser.add_argument(self.name, nargs="*", **kwargs)
        elif self.kind == SWITCH:
            parser.add_argument(self.flag, dest=self.name, action="store_true", **kwargs)
        elif self.kind == LIST:
            parser.add_argument(self.flag, dest=self.name, action="append", default=[],
                                **({"nargs": self.nargs} if self.nargs else {}), **kwargs)
        else:
            parser.add_argument(self.flag, dest=self.name, default=self.default,
                                required=self.required, **kwargs)


class OptionsObject:
    """What every command's options object does: check each field by its declaration when
    made (``OPTIONS``), and say which options were given."""
    OPTIONS: tuple[Option, ...] = ()
    ONE_OF: tuple[str, ...] = ()

    def __post_init__(self):
        for option in self.OPTIONS:
            object.__setattr__(self, option.name, option.checked(getattr(self, option.name)))
        if self.ONE_OF:
            chosen = [name for name in self.ONE_OF if getattr(self, name) not in (None, False)]
            if len(chosen) != 1:
                flags = [o.flag for o in self.OPTIONS if o.name in self.ONE_OF]
                raise SpecError("/".join(flags), chosen, f"exactly one of {', '.join(flags)}")

    def given(self) -> list[str]:
        """The options set to something other than their default, in declaration order."""
        return [f.name for f in dataclasses.fields(self)
                if getattr(self, f.name) != _default(f)]


def _default(f: dataclasses.Field):
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default


def options_class(name: str, options: tuple[Option, ...], module: str, doc: str,
                  one_of: tuple[str, ...] = ()) -> type:
    """A frozen dataclass with one field per declared option (keyword-only; a required one
    without a default), checked when made. ``module`` is where the class is assigned to
    ``name`` (so that it pickles, as a study's options cross into Dask workers)."""
    fields = []
    for option in options:
        if option.required:
            fields.append((option.name, Any, dataclasses.field(kw_only=True)))
        elif option.kind in (LIST, POSITIONALS):
            fields.append((option.name, Any, dataclasses.field(default_factory=list,
                                                               kw_only=True)))
        else:
            default = False if option.kind == SWITCH else option.default
            fields.append((option.name, Any, dataclasses.field(default=default, kw_only=True)))
    cls = dataclasses.make_dataclass(name, fields, bases=(OptionsObject,), frozen=True,
                                     namespace={"OPTIONS": tuple(options),
                                                "ONE_OF": tuple(one_of), "__doc__": doc})
    cls.__module__ = module
    return cls


@dataclass(frozen=True)
class Command:
    """A subcommand: ``run(options) -> exit status`` on its options object (``Options``).
    ``group``: the command it is an action of (``data import``), with that command's help;
    ``one_of``: options of which exactly one is given."""
    name: str
    help: str
    run: Callable[[Any], int]
    options: tuple[Option, ...]
    description: str | None = None
    one_of: tuple[str, ...] = ()
    group: tuple[str, str, str] | None = None       # (name, help, its actions' help)

    def __post_init__(self):
        title = "".join(part.title() for part in
                        (*(self.group[:1] if self.group else ()), self.name))
        object.__setattr__(self, "Options", options_class(
            f"{title}Options", self.options, self.run.__module__,
            f"The options of ``{self.prog}``.", self.one_of))

    @property
    def prog(self) -> str:
        return f"{self.group[0]} {self.name}" if self.group else self.name

    def options_from(self, namespace):
        """The options object of what the command line gave (checked as from Python)."""
        return self.Options(**{o.name: o.typed(getattr(namespace, o.name))
                               for o in self.options})

    def __call__(self, namespace) -> int:
        return self.run(self.options_from(namespace))

    def add_to(self, subparsers) -> argparse.ArgumentParser:
        parser = subparsers.add_parser(self.name, help=self.help, description=self.description)
        exclusive = parser.add_mutually_exclusive_group(required=True) if self.one_of else None
        for option in self.options:
            option.add_to(exclusive if option.name in self.one_of else parser)
        parser.set_defaults(command=self, parser=parser)
        return parser


class OneLineParser(argparse.ArgumentParser):
    """Bad options are one line too (the usage is one ``-h`` away), exit status 2; the
    subcommands' parsers are of this class as well."""

    def error(self, message):
        hint = ""
        if message.startswith("unrecognized arguments:"):    # a misspelt option: suggest
            known = [o for a in self._actions for o in a.option_strings]
            close = {m for given in message.split(":", 1)[1].split()
                     for m in difflib.get_close_matches(given, known, n=1)}
            hint = f"; did you mean {', '.join(sorted(close))}?" if close else ""
        self.exit(2, f"{self.prog}: error: {message}{hint} (see {self.prog} -h)\n")


def build_parser(prog: str, description: str, version: str,
                 commands: tuple[Command, ...]) -> argparse.ArgumentParser:
    """One parser for every declared command, in the order given."""
    parser = OneLineParser(prog=prog, description=description)
    parser.add_argument("--version", action="version", version=f"%(prog)s {version}")
    sub = parser.add_subparsers(dest="subcommand", required=True)
    groups: dict[str, Any] = {}
    for command in commands:
        where = sub
        if command.group:
            name, help_text, actions_help = command.group
            if name not in groups:
                group = sub.add_parser(name, help=help_text)
                groups[name] = group.add_subparsers(dest=f"{name}_action", required=True,
                                                    metavar="ACTION", help=actions_help)
            where = groups[name]
        command.add_to(where)
    return parser


def parse(parser: argparse.ArgumentParser, argv) -> argparse.Namespace:
    """``argv`` parsed; a misspelt option (``--quik``) is answered by its own command's
    parser (its usage and its options), not the top one's."""
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        args.parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    return args
