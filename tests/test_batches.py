"""engine.batches: runs of items in order, here or on Dask."""
import pytest

from snn_antenna.engine.batches import Batches


def squares(items):
    return [x * x for x in items]


def test_runs_are_cut_by_size_deferred_here_and_returned_in_order():
    calls = []

    def work(items):
        calls.append(list(items))
        return squares(items)

    batches = Batches(work, per_run=3)
    pending = batches.submit(list(range(7)))
    assert [p.size for p in pending] == [3, 3, 1] and calls == []   # deferred until collect
    assert batches.collect(pending) == [x * x for x in range(7)]
    assert calls == [[0, 1, 2], [3, 4, 5], [6]]


def test_a_run_that_loses_results_is_an_error_not_a_silent_shift():
    batches = Batches(lambda items: items[:-1], per_run=2)
    with pytest.raises(RuntimeError, match="2 item"):
        batches.run([1, 2, 3])
    with pytest.raises(ValueError, match="per_run"):
        Batches(squares, per_run=0)
