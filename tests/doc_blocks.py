"""The code blocks of a documentation page and the output each is shown with, for the tests
that run them as a reader would: each on its own."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_BLOCK = re.compile(r"^```(\w+)\n(.*?)^```\n", re.S | re.M)


@dataclass
class Block:
    language: str
    code: str
    expected: str | None     # the next block, when it is a ```text block: what it prints


def blocks(page: Path) -> list[Block]:
    found = [(m.group(1), m.group(2)) for m in _BLOCK.finditer(page.read_text(encoding="utf-8"))]
    out = []
    for i, (language, code) in enumerate(found):
        if language == "text":
            continue
        after = found[i + 1] if i + 1 < len(found) else None
        out.append(Block(language, code, after[1] if after and after[0] == "text" else None))
    return out


def expected_lines_missing(expected: str, output: str) -> list[str]:
    """Lines of ``expected`` that no line of ``output`` matches, in order; ``…`` in an
    expected line stands for any text (a time, a path, a hash)."""
    lines = output.splitlines()
    missing, at = [], 0
    for line in expected.strip("\n").splitlines():
        pattern = re.compile(".*".join(re.escape(part) for part in line.strip().split("…")))
        for j in range(at, len(lines)):
            if pattern.fullmatch(lines[j].strip()):
                at = j + 1
                break
        else:
            missing.append(line)
    return missing


def run_python(code: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter of this environment, from ``cwd``."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)
