"""arm_sim_ros: a planar two-link arm simulated with RK4, published as a ROS 2 node."""


def __getattr__(name):
    # `arm_sim_ros.sweep(...)`, imported when first used: `import arm_sim_ros` (every node
    # and tool does) stays as light as it was.
    if name == "sweep":
        from .tools.sweep.api import sweep
        return sweep
    raise AttributeError(f"module 'arm_sim_ros' has no attribute {name!r}")
