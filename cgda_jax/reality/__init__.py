"""From simulation to a robot: a result as a trajectory a controller can take
(`cgda_jax.reality.export`, its files `cgda_jax.reality.files`) and the replay of
that trajectory on MuJoCo C that checks it (`cgda_jax.reality.replay`).

Modules, in their import order:

1. :mod:`~cgda_jax.reality.export`: time parameterization with ruckig
   (`time_parameterize`, `trajectory_of`, `ExportedTrajectory`).
2. :mod:`~cgda_jax.reality.files`: CSV, JSON (a ROS ``JointTrajectory``) and NPZ.
3. :mod:`~cgda_jax.reality.replay`: the exported samples on MuJoCo C -> features.
"""
