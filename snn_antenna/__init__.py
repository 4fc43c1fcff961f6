"""snn-antenna: spiking neural networks (Brian2) that read an insect-inspired bionic antenna."""
__version__ = "0.2.0"
