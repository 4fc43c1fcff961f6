"""The online pipeline: samples in, the live network stepped window by window, the input
schedule that owns its inputs (Th, the rate-map window, the speed command), its handlers
(robot, terminal, a replay's journaled changes) and the stream's report."""
