"""Two runs of a study, side by side: does the second tell the first's science?

    python benchmarks/compare_runs.py OLD NEW

OLD and NEW are ``summary.json`` files or the output folders holding them (a stored page
source such as ``docs/results/gating_threshold.json`` works too). Prints one line per
predicted quantity (``report.agreement``) and a count; exits 1 when a quantity differs.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from snn_antenna.report.agreement import agreement  # noqa: E402


def _summary(path: str) -> dict:
    p = Path(path)
    return json.loads((p / "summary.json" if p.is_dir() else p).read_text())


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    rows = agreement(_summary(args[0]), _summary(args[1]))
    for row in rows:
        print(f"{row['verdict']:>15}  {row['quantity']}: {row['how']}")
    counts = {v: sum(r["verdict"] == v for r in rows) for v in dict.fromkeys(
        r["verdict"] for r in rows)}
    print(", ".join(f"{n} {v}" for v, n in counts.items()))
    return 1 if counts.get("differ") else 0


if __name__ == "__main__":
    sys.exit(main())
