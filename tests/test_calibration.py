"""Each calibrated constant is written once: in ``core.calibration``'s table, which code reads,
specs name (``"calibrated:NAME"``, or a number of their own to override it) and reports cite."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from snn_antenna.core import calibration
from snn_antenna.core import spec as specs
from snn_antenna.core.errors import SpecError

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("snn_antenna", "networks", "studies", "stimuli")
TABLE_FILE = ROOT / "snn_antenna" / "core" / "calibration.py"


def _copies(text: str) -> dict:
    found = {}
    for c in calibration.TABLE.values():
        literal = repr(c.value)
        pattern = re.compile(rf"(?<![\w.]){re.escape(literal)}(?![\w]|\.\d)")
        found[c.name] = len(pattern.findall(text))
    return found


def test_each_calibrated_value_is_written_once():
    copies = []
    for folder in SCANNED:
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix not in (".py", ".toml") or path == TABLE_FILE:
                continue
            for name, n in _copies(path.read_text(encoding="utf-8")).items():
                if n:
                    copies.append(f"{path.relative_to(ROOT)}: {name} "
                                  f"({calibration.value(name)!r}) x{n}")
    assert not copies, "copies of calibrated values (read core.calibration instead):\n" + \
        "\n".join(copies)
    assert all(n == 1 for n in _copies(TABLE_FILE.read_text()).values())


def test_the_scan_finds_a_copy():
    assert _copies("hz_per_k = 27.49  # x")["rod_hz_per_k"] == 1
    assert _copies("x = 127.49 + 27.495")["rod_hz_per_k"] == 0


def test_a_spec_names_a_value_of_the_table_or_overrides_it():
    spec = specs.load(ROOT / "studies" / "baseline_comparison.toml")
    rod = spec["spiking"]["bank"]["bands"]["rod"]
    assert rod["hz_per_k"] == calibration.value("rod_hz_per_k")
    assert spec["spiking"]["tuned"]["tuning"]["max_k_dt"] == calibration.value("rod_max_k_dt")
    mine = specs.load(ROOT / "studies" / "baseline_comparison.toml",
                      ["spiking.bank.bands.rod.hz_per_k=25.0"])
    assert mine["spiking"]["bank"]["bands"]["rod"]["hz_per_k"] == 25.0
    assert "set by the spec" in calibration.describe("rod_hz_per_k", 25.0)
    assert "speed_accuracy" in calibration.describe("rod_hz_per_k")


def test_code_reads_the_table():
    from snn_antenna.evaluation import bands
    from snn_antenna.readout.band_tuning import Tuning
    from snn_antenna.readout.spiking import HIGH_BAND

    assert bands.ROD_BAND.hz_per_k == calibration.value("rod_hz_per_k")
    assert HIGH_BAND.hz_per_k == calibration.value("high_band_hz_per_k")
    assert Tuning().max_k_dt == calibration.value("rod_max_k_dt")


def test_an_unknown_name_is_one_line():
    with pytest.raises(SpecError, match="rod_hz_per_k") as err:
        calibration.resolve({"a": {"hz_per_k": "calibrated:rod_hz"}})
    assert "a.hz_per_k" in str(err.value) and "\n" not in str(err.value)
