"""The baseline comparison's estimate counts the read-outs' fits the run makes: every read-out
it evaluates on every split, NMF's filters, shared among the workers."""
import dataclasses
import importlib

import numpy as np
import pytest
import xarray as xr

from snn_antenna.core import spec as specs
from snn_antenna.readout.spiking_decoders import (TRAINING_FREE, coder_baselines,
                                                  spiking_baselines, tuned_baselines)

from snn_antenna.studies.baseline_comparison.chosen import chosen_baselines

plan_module = importlib.import_module("snn_antenna.studies.baseline_comparison.plan")
SPEC = "studies/baseline_comparison.toml"


def _spikes(bank) -> xr.Dataset:
    """A spiking features' band labels, as the bank's cached features carry them."""
    bands = [name for name, band in bank.bands.items() for _ in range(band.n_neurons)]
    return xr.Dataset({"band": ("neuron", np.array(bands)),
                       "neuron_hz": ("neuron", np.linspace(10.0, 400.0, len(bands)))})


@pytest.mark.parametrize("quick", [False, True])
def test_every_fitted_read_out_is_counted(quick):
    parts = plan_module.plan(specs.load(SPEC, quick=quick)).parts
    ev, tuned = parts.evaluation, parts.plan.tuned_plan()
    chosen = (ev.baselines(int(parts.processor.max_hz) + 1)
              + spiking_baselines(_spikes(parts.bank), ev) + tuned_baselines(ev)
              + coder_baselines(tuned.coders, tuned.coder_sizes, ev)
              + chosen_baselines(parts.chosen, ev))
    learning = [b for b in chosen if b.name not in TRAINING_FREE]
    assert plan_module.readout_fits(parts) == (len(learning), sum(ev.nmf_dims))


def test_the_fits_scale_with_splits_and_share_the_workers():
    parts = plan_module.plan(specs.load(SPEC)).parts
    one = plan_module.readout_seconds(dataclasses.replace(
        parts, plan=dataclasses.replace(parts.plan, workers=1)))
    two = plan_module.readout_seconds(dataclasses.replace(
        parts, plan=dataclasses.replace(parts.plan, workers=2)))
    assert two == pytest.approx(one / 2)
    fewer = dataclasses.replace(parts.evaluation, seeds=[0])
    assert plan_module.readout_seconds(dataclasses.replace(
        parts, evaluation=fewer, plan=dataclasses.replace(parts.plan, workers=1))) \
        == pytest.approx(one / len(parts.evaluation.seeds))
    # the full profile's fits: 5 splits of 46 read-outs, minutes of one core
    assert 60 < one < 3600
