"""``cgda export RUN_FOLDER``: the run's result as a trajectory file a robot
controller can take (CSV, JSON with a ROS ``JointTrajectory``, NPZ), checked by its
replay on MuJoCo C.  Argument parsing and messages only; the trajectory is
`cgda_jax.experiment.trajectory_file`'s, its files `cgda_jax.reality.files`'."""

from __future__ import annotations

from cgda_jax.cli.output import Session, check_out_file, say

EXPORT_EXAMPLES = """\
examples:
  cgda export results/paint_iet                    # results/paint_iet/trajectory.json
  cgda export results/paint_iet --rate 250 --format csv
  cgda export results/paint_iet --out /tmp/paint.npz --no-check
  cgda export results/move_push_box --profile ruckig --jerk 50

Joint positions, velocities and accelerations of the evolved joints at the control
rate (default 100 Hz), from the start posture through every waypoint along the
straight joint-space moves the simulator made, each move on the run's own
minimum-jerk ramp over its move time (made longer only where the robot's velocity,
acceleration or --jerk limits need it), or with --profile ruckig jerk-limited by
ruckig within those limits, each waypoint held as long as the run held it. Units:
rad (m for a slide), per s, per s^2; the JSON's "joint_trajectory" is a ROS
trajectory_msgs/JointTrajectory field for field. Unless --no-check the file is
read back and replayed on MuJoCo C (the run's model, scene and timing) and its
features judged against the goal. Exit status: 0 written (and the replay met the
run's tolerance), 1 written but the replay did not meet it (a run that missed its
goal, or a replay that differs from it), 2 bad input, known before any work (not an
execution results folder, NaN joints or joints outside their ranges, --rate outside
1 Hz to 100 kHz, more than 1,000,000 samples, --out a folder, not writable or a
file of the run), 3 any other failure (a full disk: the earlier file is kept).
"""


def add_export_parser(sub, fmt) -> None:
    """The ``export`` sub-command on the ``cgda`` parser's sub-parsers ``sub``."""
    p = sub.add_parser(
        "export", help="write a run's result as a trajectory file for a controller",
        description="Export a run's joints as a time-parameterized trajectory.",
        epilog=EXPORT_EXAMPLES, formatter_class=fmt)
    p.add_argument("folder", help="an execution results folder (of `cgda run`)")
    p.add_argument("--rate", type=float, default=100.0, metavar="HZ",
                   help="control rate in Hz (default 100)")
    p.add_argument("--format", choices=("csv", "json", "npz"), default=None,
                   help="file format (default: --out's suffix, else json)")
    p.add_argument("--out", metavar="FILE",
                   help="the file (default: FOLDER/trajectory.FORMAT)")
    p.add_argument("--jerk", type=float, default=None, metavar="RAD_S3",
                   help="jerk limit of every joint (default: the run's own moves')")
    p.add_argument("--profile", choices=("min_jerk", "ruckig"), default="min_jerk",
                   help="each move's profile: the run's own minimum-jerk ramp "
                        "(default; what the run was judged on) or ruckig's "
                        "jerk-limited one")
    p.add_argument("--no-check", action="store_true",
                   help="do not replay the written file on MuJoCo C")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.add_argument("--no-cache", action="store_true",
                   help="do not use the persistent JAX compilation cache")


def cmd_export(args, session: Session) -> int:
    """Write the file; 0 when written (and its replay met the tolerance), 1 when
    the replay missed it (errors are raised and reported by `cgda_jax.cli`)."""
    import math

    from cgda_jax.experiment.trajectory_file import check_exported, export_trajectory
    from cgda_jax.experiment.load import load_run
    from cgda_jax.reality.control_trajectory import RATE_RANGE
    from cgda_jax.results_folder.rules import expand
    from cgda_jax.reality.files import load_trajectory, save_trajectory

    lo, hi = RATE_RANGE
    if not lo <= args.rate <= hi:
        raise ValueError(f"--rate must be in [{lo:g}, {hi:g}] Hz, got {args.rate:g}")
    if args.jerk is not None and not (math.isfinite(args.jerk) and args.jerk > 0):
        raise ValueError(f"--jerk must be a finite number > 0 rad/s^3, got "
                         f"{args.jerk:g}")
    run = load_run(args.folder)
    fmt = args.format
    if args.out:
        out = expand(args.out)
        fmt = fmt or (out.suffix.lstrip(".").lower() or "json")
        if out.suffix.lstrip(".").lower() != fmt:
            raise ValueError(f"--out {out} does not end in .{fmt} (the format)")
    else:
        fmt = fmt or "json"
        out = run.folder / f"trajectory.{fmt}"
    check_out_file(out, "--out", run.folder,
                   tuple(f"trajectory.{f}" for f in ("csv", "json", "npz")))
    sim = run.simulator()
    traj = export_trajectory(run, args.rate, jerk=args.jerk, sim=sim,
                             profile=args.profile)
    try:
        save_trajectory(traj, out, fmt)
    except OSError as err:
        raise OSError(f"{out} could not be written ({err.strerror or err}): nothing "
                      "written, an earlier file there is kept") from None
    say(session, f"[{run.name}] {traj.n_samples} samples at {traj.rate:g} Hz, "
        f"{traj.duration:.2f} s, joints {', '.join(traj.joint_names)} -> {out}")
    for s in traj.info["stretched"]:
        say(session, f"[{run.name}] move {s['move']} takes {s['export_s']:.2f} s, "
            f"longer than the run's {s['run_s']:.2f} s: the robot's limits need it")
    if args.no_check:
        return 0
    check = check_exported(run, load_trajectory(out), sim=sim)
    unit = run.result.get("error_unit") or ""
    say(session, f"[{run.name}] replayed on MuJoCo C: max point error "
        f"{check['max_point_error']:.4g} {unit} (tolerance {check['tolerance']:g}), "
        f"max feature difference from the run {check['max_feature_difference']:.3g}"
        f": {'met' if check['success'] else 'NOT met'}")
    return 0 if check["success"] else 1
