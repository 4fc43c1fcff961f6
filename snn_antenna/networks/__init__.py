"""Brian2 builders: every spiking part of the toolkit.

``neurons`` (Izhikevich equations, presets, threshold/reset, ``simulate``) is the one place the
neuron model is written; ``resonators`` (the resonator array), ``gate`` (the speed gate's
associative memory), ``cpg`` (pan/tilt rhythm), ``control`` (class-I control units) build
groups from it, and ``assembly`` puts together only the parts a network spec lists.
``reference`` holds exact (solve_ivp) solutions of the same model, used to measure accuracy.
"""
