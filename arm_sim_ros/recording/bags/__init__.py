"""rosbag2 bags (MCAP) of the arm's topics, written and read with the `rosbags` library.
May import: recording.csv_file, the base modules."""
