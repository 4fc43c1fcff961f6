"""What the networks' spikes and the sensor's samples mean: decisions a robot can make now.

Everything here sees only what a robot has at that moment (samples, coded signals, spikes,
rate maps); none of it reads ground truth (``snn_antenna.core.truth``): ``tests/test_layout.py``
fails when a module here imports it, reads a recording's ``truth`` or names a bench label.
How good the decisions were is ``snn_antenna.evaluation``'s work, afterwards.

- ``contacts``: dominant neuron, centroid, the contact rule (``ContactDetector`` offline,
  ``EpisodeTracker`` window by window live: the same code), ``detector_from_spec``.
- ``detection``: the blind read-out of coded scenes (``run_codings``: many codings as one
  Brian2 group; ``BlindReadOut``: coded columns in, detections out).
- ``closed_loop``: the exploration loop's reflexes (``steer``: the speed command and the
  freeze hold), its settings, and the robot's own record of a loop.
- ``events``: the paper's FFT/parametric features of a contact event, from its counts only.
- ``spiking`` and ``spiking_decoders``: spike features of contact events from resonator banks
  and the decoders that read them; ``baselines``: the paper's scikit-learn pipelines (MLPs,
  NMF filter bank, perceptrons) as estimators.
"""
