"""Two runs of a study, side by side: does the second tell the first's science?

    python benchmarks/compare_runs.py OLD NEW
    python benchmarks/compare_runs.py OLD NEW --paired f1_per_seed.gated

OLD and NEW are ``summary.json`` files or the output folders holding them (a stored page
source such as ``docs/results/gating_threshold.json`` works too). Prints one line per
predicted quantity (``report.agreement``) and a count; exits 1 when a quantity differs.

``--paired KEY`` (a dotted key of the summaries holding one value per seed, the seeds in the
same order in both, e.g. two runs of the gating study with different networks) prints NEW −
OLD paired by seed over the seeds both ran: mean, 95 % interval, n and its verdict
(``report.stats.paired_difference``), and exits 0.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from snn_antenna.report import stats  # noqa: E402
from snn_antenna.report.agreement import agreement  # noqa: E402


def _summary(path: str) -> dict:
    p = Path(path)
    return json.loads((p / "summary.json" if p.is_dir() else p).read_text())


def paired(old: dict, new: dict, key: str) -> str:
    """NEW − OLD of the per-seed values under the dotted ``key``, paired by seed."""
    def values(summary):
        for part in key.split("."):
            summary = summary[part]
        return summary
    a, b = values(new), values(old)
    n = min(len(a), len(b))
    iv = stats.paired_difference(a[:n], b[:n])
    return (f"{key}: new − old {iv.mean:+.4f} (95 % CI {iv.low:+.4f} to {iv.high:+.4f}, "
            f"n = {iv.n}, paired t p = {iv.p_value:.2g}: {iv.verdict}); old mean "
            f"{sum(b[:n]) / n:.4f}, new mean {sum(a[:n]) / n:.4f}")


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if len(args) == 4 and args[2] == "--paired":
        print(paired(_summary(args[0]), _summary(args[1]), args[3]))
        return 0
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
