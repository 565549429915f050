"""Rerun recordings (.rrd): telemetry, the blueprint, sinks and reading them back.
May import: physics, recording.readouts and csv_file."""
