"""The serial bridge: wire protocol, serial source, recorder, replay and device emulator.

``load_recording(DIR)`` reads back what ``snn-antenna record`` wrote, also after a crash.
"""
from .wire.recorder import BridgeRecording, load_recording

__all__ = ["BridgeRecording", "load_recording"]
