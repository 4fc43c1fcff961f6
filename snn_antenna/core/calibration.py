"""Calibrated constants: each value written once, with its unit and where it came from.

A calibrated constant is a number the toolkit was fitted to: a measurement a command of the
toolkit makes again, or a paper's figure. Code reads it with :func:`value`; a spec refers to it
as the text ``"calibrated:NAME"`` (``core.spec.load`` puts the value in its place, so a study
sees a number), or writes a number of its own to override it; a report's "Calibrated to" rows
say where a value came from with :func:`source` or :func:`describe`.

``tests/test_calibration.py`` scans the package and the specs (``networks/``, ``studies/``,
``stimuli/``) and fails on any other copy of a value in this table.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import SpecError

REFERENCE = "calibrated:"        # how a spec names a value of the table


@dataclass(frozen=True)
class Constant:
    name: str
    value: float
    unit: str
    source: str


TABLE = {c.name: c for c in (
    Constant("rod_hz_per_k", 27.49, "Hz per unit k",
             "the rod band's driven tuning sweep at an accurate step (rk2, dt 0.005 ms, "
             "90-420 Hz): the frequency each resonator fires most for, per unit k "
             "(evaluation.bands.peak_hz_per_k; snn-antenna run studies/speed_accuracy.toml, "
             "its bands section)"),
    Constant("high_band_hz_per_k", 23.46, "Hz per unit k",
             "the high band's driven tuning sweep at an accurate step (rk4, dt 0.005 ms, "
             "55-500 Hz; evaluation.bands.peak_hz_per_k; snn-antenna run "
             "studies/speed_accuracy.toml, its bands section)"),
    Constant("rod_max_k_dt", 0.0764, "model ms per step",
             "the rod band's validated k*dt: rk2 at dt 0.005 ms up to 420 Hz at rod_hz_per_k "
             "(420 / rod_hz_per_k * 0.005), its rate map within 4 % of the exact reference "
             "(evaluation.bands; snn-antenna run studies/speed_accuracy.toml)"),
)}


def value(name: str) -> float:
    """The calibrated value ``name`` (see :data:`TABLE`)."""
    return _constant(name).value


def source(name: str) -> str:
    """Where the value ``name`` came from: the paper's figure or the command that measured it."""
    return _constant(name).source


def describe(name: str, used=None) -> str:
    """One line for a report's "Calibrated to" rows: the value a run used (``used``; the
    table's when ``None``), its unit, and whether it is the table's or the spec's own."""
    c = _constant(name)
    if used is None or float(used) == c.value:
        return f"{c.value:g} {c.unit} (calibrated: {c.source})"
    return f"{float(used):g} {c.unit} (set by the spec; calibrated {c.value:g}: {c.source})"


def resolve(tree, where: str = ""):
    """``tree`` (a spec read from TOML) with every ``"calibrated:NAME"`` text replaced by
    the table's value; an unknown name is refused with one line."""
    if isinstance(tree, dict):
        return {k: resolve(v, f"{where}.{k}" if where else str(k)) for k, v in tree.items()}
    if isinstance(tree, list):
        return [resolve(v, f"{where}[{i}]") for i, v in enumerate(tree)]
    if isinstance(tree, str) and tree.startswith(REFERENCE):
        name = tree[len(REFERENCE):].strip()
        if name not in TABLE:
            raise SpecError(where or "spec", tree, "a number, or 'calibrated:NAME' with NAME "
                                                   f"one of {sorted(TABLE)}")
        return TABLE[name].value
    return tree


def referenced(tree):
    """``tree`` with every number equal to a table value written as its ``"calibrated:NAME"``
    text (``resolve``'s inverse), so a spec a run writes names the constants it used rather
    than copying them."""
    if isinstance(tree, dict):
        return {k: referenced(v) for k, v in tree.items()}
    if isinstance(tree, list):
        return [referenced(v) for v in tree]
    if isinstance(tree, float):
        return next((REFERENCE + c.name for c in TABLE.values() if c.value == tree), tree)
    return tree


def _constant(name: str) -> Constant:
    try:
        return TABLE[name]
    except KeyError:
        raise SpecError("calibrated constant", name, f"one of {sorted(TABLE)}") from None
