"""The grid of a sweep: named axes, their Cartesian product, and its chunks.

``Grid(axes)``: named axes, each a list of values or a range ``{start, stop, num, scale =
"linear" | "log"}`` (``axis_values``). Points are the Cartesian product in axis order;
``blocks(chunk_points)`` cuts the grid into rectangular chunks of at most ``chunk_points``
points that keep the trailing axes whole (a tuning curve stays in one chunk).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.bounds import memory_budget_bytes
from ..core.errors import SpecError, check, is_integer


# The least any sweep holds per grid point: one float64 (each axis's coordinate, each output).
BYTES_PER_POINT = 8


def fits_in_memory(field: str, value, need_bytes: float, what: str, remedy: str,
                   budget: int | None = None) -> None:
    """Refuse ``need_bytes`` beyond the memory budget (a quarter of the memory available) in
    one line naming ``field``: the cost guard's one wording, before anything is allocated."""
    budget = memory_budget_bytes() if budget is None else budget
    check(need_bytes <= budget, field, value,
          f"{what} in memory: {need_bytes / 1e9:.3g} GB needed, {budget / 1e9:.3g} GB "
          f"allowed (a quarter of the memory available); {remedy}")


def _range(name: str, value: dict) -> tuple[float, float, int, str]:
    """A range axis's ``start, stop, num, scale``, checked (nothing allocated)."""
    unknown = set(value) - {"start", "stop", "num", "scale"}
    check(not unknown and {"start", "stop", "num"} <= set(value), f"axes.{name}", value,
          "a list of values or a range {start, stop, num, scale = 'linear' | 'log'}")
    start, stop, num = value["start"], value["stop"], value["num"]
    scale = value.get("scale", "linear")
    check(isinstance(num, int) and not isinstance(num, bool) and num >= 1,
          f"axes.{name}.num", num, "an integer number of values >= 1")
    check(scale in ("linear", "log"), f"axes.{name}.scale", scale, "'linear' or 'log'")
    check(all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
              for x in (start, stop)), f"axes.{name}", value, "finite start and stop")
    if scale == "log":
        check(start > 0 and stop > 0, f"axes.{name}", value,
              "start and stop > 0 for a log-spaced axis")
    fits_in_memory(f"axes.{name}.num", num, num * BYTES_PER_POINT, "axis values that fit",
                   "lower num")
    return start, stop, num, scale


def axis_length(name: str, value) -> int:
    """How many values an axis has, without making them."""
    if isinstance(value, dict):
        return _range(name, value)[2]
    return int(np.size(value)) if isinstance(value, (list, tuple, np.ndarray)) else 1


def axis_values(name: str, value) -> np.ndarray:
    """Values of one axis: a list of numbers, or ``{start, stop, num, scale}`` (scale
    ``"linear"``, the default, or ``"log"``; stop included)."""
    if isinstance(value, dict):
        start, stop, num, scale = _range(name, value)
        space = np.geomspace if scale == "log" else np.linspace
        values = space(start, stop, num)
    else:
        raw = value if isinstance(value, (list, tuple, np.ndarray)) else [value]
        try:
            values = np.asarray(raw, dtype=float).ravel()
        except (TypeError, ValueError, OverflowError):     # an int beyond any float, too
            raise SpecError(f"axes.{name}", value, "numbers") from None
    check(values.size >= 1, f"axes.{name}", value, "at least one value (the axis is empty)")
    check(bool(np.all(np.isfinite(values))), f"axes.{name}", value, "finite values")
    check(np.unique(values).size == values.size, f"axes.{name}", value,
          "distinct values (a repeated value would make the coordinate ambiguous)")
    return values


class Grid:
    """The Cartesian product of named axes (see the module docstring)."""

    def __init__(self, axes: dict[str, Any], units: dict[str, str] | None = None):
        check(isinstance(axes, dict) and len(axes) >= 1, "axes", axes,
              "a table of at least one named axis")
        check(units is None or (isinstance(units, dict) and all(
            isinstance(u, str) for u in units.values())), "units", units,
            "a table of axis name -> unit text")
        shape = [axis_length(name, v) for name, v in axes.items()]
        points = math.prod(shape)
        fits_in_memory("axes", " × ".join(map(str, shape)) + f" = {points:,} points",
                       points * BYTES_PER_POINT, "a grid whose points fit",
                       "shrink an axis or split the sweep")
        self.axes = {str(name): axis_values(name, v) for name, v in axes.items()}
        self.units = dict(units or {})

    @classmethod
    def from_spec(cls, table: dict, known: dict[str, str] | None = None) -> Grid:
        """A grid from a spec's ``[axes]`` table; ``known`` maps accepted axis names to units."""
        check(isinstance(table, dict) and len(table) >= 1, "axes", table,
              "a table of at least one named axis")
        if known is not None:
            for name in table:
                check(name in known, f"axes.{name}", table[name],
                      f"an axis this study can sweep: {', '.join(known)}")
        return cls(table, {n: known[n] for n in table} if known else None)

    @property
    def dims(self) -> tuple[str, ...]:
        return tuple(self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.axes.values())

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def block_shape(self, chunk_points: int) -> tuple[int, ...]:
        """Chunk shape: trailing axes whole while they fit, then a part of the next axis."""
        check(is_integer(chunk_points) and chunk_points >= 1, "chunk_points",
              chunk_points, "an integer >= 1 (not true/false)")
        block, room = [], chunk_points
        for n in reversed(self.shape):
            take = max(1, min(n, room))
            block.append(take)
            room = max(1, room // take) if take == n else 1
        return tuple(reversed(block))

    def blocks(self, chunk_points: int) -> list[dict[str, slice]]:
        """The chunks, in C order, as regions {axis: slice}."""
        block = self.block_shape(chunk_points)
        counts = [math.ceil(n / b) for n, b in zip(self.shape, block)]
        regions = []
        for index in np.ndindex(*counts):
            regions.append({dim: slice(i * b, min((i + 1) * b, n)) for dim, i, b, n in
                            zip(self.dims, index, block, self.shape)})
        return regions

    def points(self, region: dict[str, slice] | None = None) -> dict[str, np.ndarray]:
        """Each axis's value at every point of ``region`` (flattened in C order)."""
        region = region or {d: slice(None) for d in self.dims}
        mesh = np.meshgrid(*(self.axes[d][region[d]] for d in self.dims), indexing="ij")
        return {d: m.ravel() for d, m in zip(self.dims, mesh)}

    def coords(self) -> dict[str, np.ndarray]:
        return dict(self.axes)

    def describe(self) -> str:
        return " × ".join(f"{d} ({n})" for d, n in zip(self.dims, self.shape)) + \
            f" = {self.size:,} points"
