"""How good the read-outs' decisions were: everything that reads ground truth or a reference.

This stage comes after ``snn_antenna.readout`` (it may import it; the read-out may never import
this): decisions are made blind, then scored here against the labels of their recordings
(``snn_antenna.core.truth``) or against the exact reference solutions.

- ``scoring``: detections against a recording's contacts, per contact (``score``,
  ``score_with``, ``score_run``, ``first_match``, ``contact_rows``, ``SCORE_OUTPUTS``).
- ``thresholds`` and ``threshold_figures``: Th*(speed) from scored sweeps; lookup table and
  gate compared on the same scenes, with intervals.
- ``crossval``: the bench's pipelines trained and tested on labelled events, split by
  repetition (``Evaluation``, ``evaluate``, ``run_designs``); ``signal``: the bench features
  with their labels, and the signal's statistics beside the paper's; ``comparison``,
  ``confusion``, ``comparison_figures``: the baseline comparison's tables and figures.
- ``accuracy``: error against the exact reference and the stability map; ``bands``: each
  spiking band measured against the reference; ``tradeoff``: Pareto fronts and
  recommendations; ``tuning``: tuning curves and the k → frequency calibration.
"""
