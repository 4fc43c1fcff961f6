"""What the networks' spikes mean, and how well: rate maps to contacts and distances.

``contacts`` (dominant neuron, centroid, the contact rule, ``ContactDetector``), ``spiking``
(features of contact events from resonator banks), ``events`` (the paper's FFT/parametric
event features), ``baselines`` (scikit-learn baselines: MLPs, NMF, perceptrons),
``scoring`` (detections against ground truth, after the run) and ``accuracy`` (error
against the exact reference, stability maps).
"""
