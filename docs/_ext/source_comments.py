"""Show on the API pages what the source says beside a setting or a constant.

The package describes a dataclass field and a module constant by a comment beside it (on its
line, or the lines just above), where a reader of the code looks. This extension puts the same
words on the API pages, so they are written once:

- a dataclass (a study's section, a network part) gets a numpy-style "Parameters" section: each
  field with its annotation, its default and its comment (napoleon renders it);
- a module constant in capitals with such a comment is documented with it (autodoc documents
  a module's data only where Sphinx's source analyzer found a ``#:`` comment; the analyzer is
  taught to read the package's plain comments too).
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import re
import sys
import tokenize
from functools import cache

from plain_docstrings import _escape  # the same escaping as every docstring's text

_CONSTANT = re.compile(r"^_?[A-Z][A-Z0-9_]*$")


@cache
def _source(module_name: str) -> tuple[str, dict[int, str]] | None:
    """A module's source and its comments by line (1-based), or None without source."""
    module = sys.modules.get(module_name)
    try:
        text = inspect.getsource(module)
    except (OSError, TypeError):
        return None
    comments = {}
    for token in tokenize.generate_tokens(io.StringIO(text).readline):
        if token.type == tokenize.COMMENT:
            comments[token.start[0]] = token.string.lstrip("#").strip()
    return text, comments


#: a comment that divides a module into sections (``# -- figures -----``)
_DIVIDER = re.compile(r"-+ .*-{3,}$|-{3,}$")


def _comment(comments: dict[int, str], lines: list[str], node: ast.stmt) -> str:
    """The comment on a statement's first line, else the comment lines just above it."""
    if node.lineno in comments and lines[node.lineno - 1].lstrip()[:1] != "#":
        return comments[node.lineno]
    above, at = [], node.lineno - 1
    while at >= 1 and lines[at - 1].lstrip().startswith("#"):
        if _DIVIDER.match(comments.get(at, "")):   # a section's title in the source: not
            break                                  # the statement's description
        above.insert(0, comments.get(at, ""))
        at -= 1
    return " ".join(above)


def _class_node(tree: ast.Module, qualname: str) -> ast.ClassDef | None:
    body = tree.body
    node = None
    for part in qualname.split("."):
        node = next((n for n in body if isinstance(n, ast.ClassDef) and n.name == part), None)
        if node is None:
            return None
        body = node.body
    return node


def field_descriptions(cls) -> dict[str, tuple[str, str]]:
    """Each field of the dataclass ``cls``: (its annotation as written, its comment)."""
    found = _source(cls.__module__)
    if found is None:
        return {}
    text, comments = found
    lines = text.splitlines()
    node = _class_node(ast.parse(text), cls.__qualname__)
    if node is None:
        return {}
    return {stmt.target.id: (ast.get_source_segment(text, stmt.annotation) or "",
                             _comment(comments, lines, stmt))
            for stmt in node.body
            if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)}


def _default(field: dataclasses.Field) -> str:
    if field.default is not dataclasses.MISSING:
        return f"default ``{field.default!r}``"
    if field.default_factory is not dataclasses.MISSING:
        return "default: made anew for each object"
    return "required"


def parameters_section(cls) -> list[str]:
    """The numpy-style "Parameters" lines of a dataclass's fields (empty without fields)."""
    described = field_descriptions(cls)
    out = []
    for field in dataclasses.fields(cls):
        if not field.init or field.name.startswith("_"):
            continue
        annotation, comment = described.get(field.name, ("", ""))
        head = f"{field.name} : {annotation + ', ' if annotation else ''}{_default(field)}"
        out += [head, *([f"    {_escape(comment)}"] if comment else [])]
    return ["", "Parameters", "----------", *out] if out else []


def _process(app, what, name, obj, options, lines: list[str]) -> None:
    if what == "class" and dataclasses.is_dataclass(obj) and "Parameters" not in lines:
        lines.extend(parameters_section(obj))


def module_constants(source: str) -> dict[str, str]:
    """The module-level constants in capitals of ``source`` with their comments."""
    comments = {token.start[0]: token.string.lstrip("#").strip()
                for token in tokenize.generate_tokens(io.StringIO(source).readline)
                if token.type == tokenize.COMMENT}
    lines = source.splitlines()
    found = {}
    for stmt in ast.parse(source).body:
        targets = (stmt.targets if isinstance(stmt, ast.Assign)
                   else [stmt.target] if isinstance(stmt, ast.AnnAssign) else [])
        for target in targets:
            if isinstance(target, ast.Name) and _CONSTANT.match(target.id):
                comment = _comment(comments, lines, stmt)
                if comment and not target.id.startswith("_"):
                    found[target.id] = comment
    return found


def _first_colon_ends_a_line(text: str) -> list[str]:
    """``text`` as lines, the first ending at its first colon: napoleon reads a data
    docstring's first line as "type: description" unless its colon ends the line."""
    head, colon, rest = text.partition(": ")
    return [head + ":", rest] if colon else [text]


def _with_commented_constants(analyze):
    """Sphinx's source analyzer, which documents a module attribute by a ``#:`` comment, here
    also by the plain comment beside a constant of this package (autodoc documents a module's
    data only where the analyzer found its documentation)."""
    def wrapped(self) -> None:
        done = self._analyzed
        analyze(self)
        if done or not self.modname.split(".")[0] == "snn_antenna":
            return
        for name, comment in module_constants(self.code).items():
            self.attr_docs.setdefault(("", name), [*_first_colon_ends_a_line(_escape(comment)),
                                                   ""])
    return wrapped


def setup(app):
    # after plain_docstrings (400) has read the docstring as plain text, before napoleon
    # (500) turns the "Parameters" section into reST
    app.connect("autodoc-process-docstring", _process, priority=450)
    from sphinx.pycode import ModuleAnalyzer
    ModuleAnalyzer.analyze = _with_commented_constants(ModuleAnalyzer.analyze)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
