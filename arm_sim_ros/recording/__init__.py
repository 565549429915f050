"""Recordings of a run or a node: Rerun (.rrd), CSV, rosbag2 and MCAP."""
import os

# A node writes its .rrd without rerun's footer (sinks.py), and rerun warns of that at every
# open; docs/guides/recordings.md says it once instead. rerun reads RUST_LOG when it makes its first
# stream, after this package is imported; "warn" is its default, a user's RUST_LOG wins.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd::file_sink=error")
