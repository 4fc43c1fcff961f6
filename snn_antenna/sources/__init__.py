"""Where signals come from: the antenna's physics, waveforms, robot scenes and the bench set.

``antenna`` (rod and sensor physics, materials, ADC) → ``stimuli`` (waveforms, ``RobotScene``)
→ ``scenes`` (courses with obstacles, scene specs) → ``bench`` (the paper's bench data set).
The serial bridge (``snn_antenna.bridge``) is the live source; it emits the same ``Recording``.
Nothing here imports from later stages (preprocess, networks, readout, engine, studies).
"""
