"""The bench data set: seeded, independent of worker count, cached by its spec, refusals."""
import numpy as np
import pytest

from snn_antenna.core.errors import SpecError
from snn_antenna.sources import bench

SMALL = dict(materials=("wood", "aluminium"), positions_cm=(10.0, 30.0), repetitions=3,
             duration_s=0.3)


def test_labels_follow_the_protocol_and_generation_is_seeded():
    spec = bench.BenchSpec(**SMALL)
    a, b = bench.generate(spec, log=lambda *_: None), bench.generate(spec, log=lambda *_: None)
    assert a.sizes["event"] == spec.n_events == 12
    assert np.array_equal(a["counts"].values, b["counts"].values)
    assert list(np.unique(a["repetition"].values)) == [0, 1, 2]
    assert set(zip(a["material"].values, a["distance_cm"].values)) == {
        (m, d) for m in SMALL["materials"] for d in SMALL["positions_cm"]}
    other = bench.generate(bench.BenchSpec(**SMALL, seed=1), log=lambda *_: None)
    assert not np.array_equal(a["counts"].values, other["counts"].values)


def test_the_same_data_on_two_processes():
    spec = bench.BenchSpec(**SMALL)
    one = bench.generate(spec, log=lambda *_: None)
    two = bench.generate(bench.BenchSpec(**SMALL, n_jobs=2), log=lambda *_: None)
    assert np.array_equal(one["counts"].values, two["counts"].values)


def test_cache_is_reused_and_keyed_by_the_spec(tmp_path):
    messages = []
    spec = bench.BenchSpec(**SMALL, cache_dir=str(tmp_path))
    first = bench.load(spec, log=messages.append)
    again = bench.load(spec, log=messages.append)
    assert any("reusing" in m for m in messages)
    assert np.array_equal(first["counts"].values, again["counts"].values)
    assert bench.BenchSpec(**SMALL, cache_dir="elsewhere", n_jobs=2).key() == spec.key()
    assert bench.BenchSpec(**{**SMALL, "repetitions": 4}).key() != spec.key()
    assert not list(tmp_path.glob("*.partial"))


def test_event_recording_carries_its_contact():
    ds = bench.generate(bench.BenchSpec(**SMALL), log=lambda *_: None)
    rec = bench.event_recording(ds, 4)
    (contact,) = rec.truth.contacts
    assert contact.material == str(ds["material"].values[4])
    assert contact.distance_cm == float(ds["distance_cm"].values[4])
    assert rec.rate_hz == 2000.0 and rec.samples.shape[1] == 2


@pytest.mark.parametrize("change,field", [
    ({"materials": ("wood", "granite")}, "material"),
    ({"rate_hz": 100.0}, "rate_hz"),
    ({"positions_cm": (50.0,)}, "distance_cm"),
    ({"repetitions": 0}, "repetitions"),
])
def test_bad_specs_are_refused(change, field):
    with pytest.raises(SpecError, match=field):
        bench.BenchSpec(**{**SMALL, **change}).validate()


def test_a_reused_store_gives_back_plain_text_labels(tmp_path):
    """Zarr v3 returns text as StringDType; the cache hands back the labels it was given."""
    spec = bench.BenchSpec(**SMALL, cache_dir=str(tmp_path))
    made = bench.load(spec, log=lambda *_: None)
    again = bench.load(spec, log=lambda *_: None)
    for name in ("material", "axis"):
        assert again[name].dtype.kind == "U", (name, again[name].dtype)
        assert list(again[name].values) == list(made[name].values)
    assert again.sel(axis="x")["counts"].shape == made.sel(axis="x")["counts"].shape


def test_the_cache_key_follows_the_antenna_physics(monkeypatch, tmp_path):
    """A change in antenna.py's source (the physics) makes a new data set: the key covers the
    package's source (``provenance.code_hash``)."""
    import shutil

    from snn_antenna.core import provenance
    spec = bench.BenchSpec(**SMALL)
    before = spec.key()
    copy = tmp_path / "snn_antenna"
    shutil.copytree(provenance.PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    physics = copy / "sources" / "antenna.py"
    physics.write_text(physics.read_text().replace("ROD_COUPLING = ", "ROD_COUPLING = 2 * "))
    monkeypatch.setattr(provenance, "PACKAGE", copy)
    provenance.code_hash.cache_clear()
    try:
        assert spec.key() != before
    finally:
        provenance.code_hash.cache_clear()
