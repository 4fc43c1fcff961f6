"""Read the package's docstrings as the plain text they are written in.

The docstrings are prose with ``double back-quoted`` names, indented code examples and aligned
tables; they use no reST directives. Read as reST, an aligned table or an absolute value
``|x|`` would be taken for markup. Before autodoc renders a docstring this extension:

- keeps each paragraph whose lines share one indentation (or form a ``-`` list) as prose;
- turns an indented paragraph (a code example) and a paragraph of mixed indentation (an
  aligned table) into a literal block, shown as written;
- escapes ``|`` and ``*`` outside double back-quotes, so they stay characters.
"""

from __future__ import annotations

import re

_LITERAL = re.compile(r"(``.+?``)")
_BULLET = re.compile(r"^(\s*)([-*•]|\d+[.)]) +")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _escape(text: str) -> str:
    """``|`` and ``*`` as characters, outside inline literals."""
    parts = _LITERAL.split(text)
    for i in range(0, len(parts), 2):
        parts[i] = parts[i].replace("\\", "\\\\").replace("|", "\\|").replace("*", "\\*")
    return "".join(parts)


def _is_prose(block: list[str], base: int) -> bool:
    """One indentation, or a list whose continuation lines hang under each item's text."""
    if _indent(block[0]) > base:
        return False
    hang = None
    for line in block:
        bullet = _BULLET.match(line)
        if bullet:
            hang = len(bullet.group(0))
            if _indent(line) != base:
                return False
        elif _indent(line) not in (base, hang):
            return False
    return True


def plain_lines(lines: list[str]) -> list[str]:
    """The docstring's lines, rewritten as reST that shows what they say."""
    out: list[str] = []
    block: list[str] = []
    base = min((_indent(line) for line in lines if line.strip()), default=0)

    def flush() -> None:
        if not block:
            return
        if _is_prose(block, base):
            out.extend(_escape(line) for line in block)
        else:
            out.extend(["::", ""])
            out.extend("    " + line for line in block)
        out.append("")
        block.clear()

    for line in lines:
        if line.strip():
            block.append(line)
        else:
            flush()
    flush()
    while out and not out[-1]:
        out.pop()
    return out


def _process(app, what, name, obj, options, lines: list[str]) -> None:
    lines[:] = plain_lines(lines)


def _skip(app, what, name, obj, skip, options):
    # scikit-learn's metadata-routing setters (set_fit_request, ...) are generated on every
    # estimator; they belong to scikit-learn's documentation, not to ours
    if name.startswith("set_") and name.endswith("_request"):
        return True
    return None


def setup(app):
    app.connect("autodoc-process-docstring", _process, priority=400)
    app.connect("autodoc-skip-member", _skip)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
