"""What the networks' spikes mean, and how well: rate maps to contacts, distances, materials.

- ``contacts``: dominant neuron, centroid, the contact rule (``ContactDetector`` offline,
  ``EpisodeTracker`` window by window live: the same code), ``detector_from_spec``.
- ``scoring``: detections against ground truth after the run (``score``, ``first_match``,
  ``contact_rows``, ``BlindReadOut``); ``thresholds`` and ``threshold_figures``: Th*(speed),
  lookup table and gate comparisons with intervals; ``closed_loop``: the exploration loop.
- ``spiking`` and ``spiking_decoders``: spike features of contact events from resonator banks
  and the decoders that read them; ``events``: the paper's FFT/parametric event features;
  ``baselines``: scikit-learn baselines (MLPs, NMF, perceptrons); ``comparison``,
  ``confusion``, ``comparison_figures``: the baseline comparison's tables and figures.
- ``accuracy``: error against the exact reference and the stability map; ``tradeoff``: Pareto
  fronts and recommendations; ``tuning``: tuning curves and the k → frequency calibration.
"""
