"""A board without hardware: the emulator (stimuli, faults), its links (pseudo-terminals,
pyserial URLs) and the shipped firmware's loop in simavr."""
