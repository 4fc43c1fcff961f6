"""The one zarr writer/reader: text coordinates and variables survive a round trip."""
from __future__ import annotations

import numpy as np
import xarray as xr

from snn_antenna.core.store import read_dataset, write_dataset


def _with_text() -> xr.Dataset:
    return xr.Dataset(
        {"counts": (("event",), np.arange(3.0), {"units": "ADC counts"}),
         "band": (("event",), np.array(["low", "mid", "hïgh"]))},
        coords={"event": np.arange(3), "material": ("event", np.array(["wood", "alu", "foam"])),
                "axis": ["x", "y"]})


def test_text_coords_and_variables_read_back_as_plain_numpy_strings(tmp_path):
    """A cached store must be interchangeable with the data set it was built from: the
    studies call ``.values.astype(str)`` and ``np.isin`` on material names, which fails on
    Zarr v3's StringDType (the crash of a second ``run studies/baseline_comparison.toml``)."""
    ds = _with_text()
    write_dataset(ds, tmp_path / "d.zarr")
    back = read_dataset(tmp_path / "d.zarr")
    for name in ("material", "band", "axis"):
        assert back[name].dtype.kind == "U", (name, back[name].dtype)
        assert list(back[name].values.astype(str)) == list(ds[name].values)
    assert np.isin(back["material"].values.astype(str), ["wood", "foam"]).sum() == 2
    assert back["counts"].attrs["units"] == "ADC counts"
    xr.testing.assert_identical(back, ds)


def test_a_second_write_over_a_store_read_back_round_trips_again(tmp_path):
    """Run twice: the second run writes what it read from the first run's store."""
    write_dataset(_with_text(), tmp_path / "d.zarr")
    write_dataset(read_dataset(tmp_path / "d.zarr"), tmp_path / "d.zarr")
    back = read_dataset(tmp_path / "d.zarr")
    xr.testing.assert_identical(back, _with_text())
    assert sorted(back["material"].values.astype(str)) == ["alu", "foam", "wood"]
    assert not (tmp_path / "d.zarr.partial").exists()
