"""The wire: the board's frame protocol, the serial source that reads it, the recorder that
keeps every byte, and replay of a recording."""
