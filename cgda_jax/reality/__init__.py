"""From simulation to a robot: a result as a trajectory a controller can take
(`cgda_jax.reality.control_trajectory`, its files `cgda_jax.reality.files`), the
replay of that trajectory on MuJoCo C that checks it (`cgda_jax.reality.replay`), and the
robot interface a result can be executed on (`cgda_jax.reality.protocol`, with a
mismatched MuJoCo world as the shipped implementation).

Modules, in their import order:

1. :mod:`~cgda_jax.reality.profiles`: one move's profile (the run's minimum-jerk
   ramp, or ruckig's jerk-limited one).
2. :mod:`~cgda_jax.reality.control_trajectory`: time parameterization along the run's
   straight moves (`time_parameterize`, `trajectory_of`, `ExportedTrajectory`).
3. :mod:`~cgda_jax.reality.files`: CSV, JSON (a ROS ``JointTrajectory``) and NPZ.
4. :mod:`~cgda_jax.reality.replay`: the exported samples on MuJoCo C -> features.
5. :mod:`~cgda_jax.reality.protocol`: the `Reality` a result runs against (the
   user's robot driver implements it), `measure` (a checked call).
6. :mod:`~cgda_jax.reality.mismatch`: the shipped `Reality`, a `MismatchedWorld`
   (the scene in MuJoCo C with perturbed masses, friction, joint offsets, damping,
   gains, feature noise and delay: `Mismatch`).
7. :mod:`~cgda_jax.reality.calibrate`: joint offsets estimated from the measured
   tool (`estimate_offsets`, `OffsetEstimate`), as the closed loop keeps them.
"""
