"""Recordings of a real antenna turned into a labelled data set the studies read.

``snn-antenna data import RECORDINGS LABELS --out DIR``: ``inputs`` reads the recordings (folders
written by ``snn-antenna record``, CSV, NumPy, WAV, ROS 2 bags), ``labels`` the labels table,
``segment`` finds the contacts by the paper's onset rule and matches them to the labels, and
``importer`` checks all of it before writing anything, then writes the data set
(``sources.recorded`` reads it). This stage comes after the bridge: reading a ``record`` folder
is the wire's job.
"""
