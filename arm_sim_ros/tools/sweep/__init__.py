"""`arm-sim sweep` and `arm_sim_ros.sweep(...)`: a scene run over grids and distributions of
its keys, one table row per sample, on every core or a Dask cluster, the same bytes wherever."""
