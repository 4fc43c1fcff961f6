"""Do two runs of a study tell the same science? Their predicted numbers, side by side.

    rows = agreement(old_summary, new_summary)     # one row per predicted quantity
    python benchmarks/compare_runs.py OLD NEW       # summaries or output folders

A study's ``summary.json`` lists what it predicts (``predicted``: value, interval, n). Two
runs agree on a quantity with intervals when the intervals overlap; on one without (a
deterministic single run) when the values are equal to ``RTOL``. A quantity only one run
has is listed as such, never counted as agreeing.
"""
from __future__ import annotations

import math

RTOL = 1e-6


def _number(value):
    return value if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _overlap(a, b) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _interval(entry):
    iv = entry.get("interval")
    if isinstance(iv, (list, tuple)) and len(iv) == 2 and all(_number(x) is not None
                                                              for x in iv):
        return tuple(float(x) for x in iv)
    return None


def compare_entry(old: dict, new: dict) -> tuple[str, str]:
    """(verdict, how) for one predicted quantity in two runs: "agree", "differ" or "not
    comparable" (a value that is not a number)."""
    a, b = _number(old.get("value")), _number(new.get("value"))
    ia, ib = _interval(old), _interval(new)
    if ia is not None and ib is not None:
        ok = _overlap(ia, ib)
        return ("agree" if ok else "differ",
                f"[{ia[0]:.4g}, {ia[1]:.4g}] (n={old.get('n')}) vs "
                f"[{ib[0]:.4g}, {ib[1]:.4g}] (n={new.get('n')}): intervals "
                f"{'overlap' if ok else 'apart'}")
    if a is not None and b is not None:
        ok = math.isclose(a, b, rel_tol=RTOL, abs_tol=RTOL)
        return "agree" if ok else "differ", f"{a:.6g} vs {b:.6g} (no interval: equal to {RTOL:g})"
    if old.get("value") == new.get("value"):
        return "agree", "the same value"
    return "not comparable", f"{old.get('value')!r} vs {new.get('value')!r}"


def agreement(old: dict, new: dict) -> list[dict]:
    """One row per predicted quantity of either summary: quantity, verdict, how."""
    before = {e["quantity"]: e for e in old.get("predicted", []) if "quantity" in e}
    after = {e["quantity"]: e for e in new.get("predicted", []) if "quantity" in e}
    rows = []
    for quantity in dict.fromkeys([*before, *after]):
        if quantity not in before or quantity not in after:
            rows.append({"quantity": quantity, "verdict": "in one run only",
                         "how": "first run" if quantity in before else "second run"})
            continue
        verdict, how = compare_entry(before[quantity], after[quantity])
        rows.append({"quantity": quantity, "verdict": verdict, "how": how})
    return rows
