"""Physics: the arm, its effects and the steppers, with no ROS, Rerun or middleware imports.
May import: the package's base modules (usage, yaml_files) only."""
