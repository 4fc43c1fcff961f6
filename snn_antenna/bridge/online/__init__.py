"""The online pipeline: samples in, the live network stepped window by window, its handlers
(contacts, robot, terminal, controls) and the stream's report."""
