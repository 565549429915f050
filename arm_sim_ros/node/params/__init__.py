"""The node's parameters and their live changes: declared once, read from --ros-args and
files, each change built aside and checked. May import: physics, the base modules."""
