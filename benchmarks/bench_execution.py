"""Raw execution throughput on TEO: cgda_jax's Simulator vs MuJoCo C.

Populations of P random joint trajectories (N = 17 waypoints, TEO's right arm as in
the experiments: 3 evolved joints, forearm fixed) are executed:

- kinematic mode (``substeps`` forward-kinematics sub-steps per waypoint, marker
  scene): ours (jitted vmap, chain kinematics; ``--mjx-kinematics`` adds the
  ``mjx.kinematics`` back-end) vs a Python loop over MuJoCo's C ``mj_kinematics``
  (benchmarks/peers.py `MujocoMarker`, same numbers, checked here; timed on at most
  ``--c-max`` candidates, the rate extrapolated);
- dynamic mode: see bench_dynamic.py (our MuJoCo C and MJX backends vs
  ``mujoco.rollout`` on the same simulated model and controls).

Rates are candidates x waypoints per second; kinematic rows also give marker
evaluations per second (x substeps). Target (2-core CPU): kinematic execution at
P = 1,024 >= 3 million marker evaluations per second.

    python benchmarks/bench_execution.py [--pops 64 1024 16384] [--repeats 5] [--quick]
"""

from __future__ import annotations

import argparse
import math
import time

import jax
import jax.numpy as jnp
import numpy as np
import peers
from _common import (
    compile_jax,
    find_row,
    median_time,
    print_table,
    report_target,
    write_json,
)

from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path

JOINTS = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
FIXED = {"r_forearm_rotation": math.radians(45.0)}
N_WAYPOINTS = 17
TARGET_MARKER_EVALS = 3e6


def population(robot: Robot, p: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    return rng.uniform(lo, hi, size=(p, N_WAYPOINTS, robot.n_dof)).astype(np.float32)


def bench_ours(
    sim: Simulator, pop: np.ndarray, repeats: int
) -> tuple[dict, np.ndarray]:
    x = jnp.asarray(pop)
    compiled, t_compile = compile_jax(jax.vmap(sim.execute), x)
    out = np.asarray(compiled(x))
    t = median_time(lambda: compiled(x), repeats=repeats)
    return {"compile_s": t_compile, "time_s": t}, out


def kinematic(args, robot) -> list[dict]:
    rows = []
    sims = {"cgda_jax chain": Simulator(robot, MarkerScene(), substeps=args.substeps)}
    if args.mjx_kinematics:
        sims["cgda_jax mjx.kinematics"] = Simulator(
            robot.with_kinematics("mjx"), MarkerScene(), substeps=args.substeps
        )
    c_sim = peers.MujocoMarker.from_simulator(sims["cgda_jax chain"])
    for p in args.pops:
        pop = population(robot, p)
        wp = p * N_WAYPOINTS
        for name, sim in sims.items():
            print(f"kinematic P={p} {name} ...", flush=True)
            r, out = bench_ours(sim, pop, args.repeats)
            rows.append(
                {
                    "mode": "kinematic",
                    "P": p,
                    "method": name,
                    **r,
                    "waypoints_per_s": wp / r["time_s"],
                    "marker_evals_per_s": wp * args.substeps / r["time_s"],
                }
            )
        print(f"kinematic P={p} MuJoCo C loop ...", flush=True)
        n_c = min(p, args.c_max)
        t0 = time.perf_counter()
        c_out = np.stack([c_sim.execute(w) for w in pop[:n_c]])
        t_c = (time.perf_counter() - t0) * p / n_c
        err = float(np.max(np.abs(c_out - out[:n_c])))
        rows.append(
            {
                "mode": "kinematic",
                "P": p,
                "method": "MuJoCo C loop",
                "compile_s": "",
                "time_s": t_c,
                "waypoints_per_s": wp / t_c,
                "marker_evals_per_s": wp * args.substeps / t_c,
                "note": f"timed on {n_c}; max|diff| {err:.1e} m",
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pops", type=int, nargs="*", default=[64, 1024, 16384])
    parser.add_argument("--substeps", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--c-max", type=int, default=256)
    parser.add_argument("--mjx-kinematics", action="store_true")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.pops, args.repeats, args.c_max = [64, 1024], 2, 32

    robot = Robot.from_mjcf(model_path("teo.xml"), JOINTS, "marker", FIXED)
    rows = kinematic(args, robot)
    print_table(
        rows,
        [
            "mode",
            "P",
            "method",
            "compile_s",
            "time_s",
            "waypoints_per_s",
            "marker_evals_per_s",
            "note",
        ],
    )
    row = find_row(rows, mode="kinematic", P=1024, method="cgda_jax chain")
    at_1024 = None if row is None else row["marker_evals_per_s"]
    report_target(
        "kinematic P=1024 >= 3e6 marker evaluations/s",
        at_1024,
        at_1024 is not None and at_1024 >= TARGET_MARKER_EVALS,
    )
    write_json(
        "bench_execution",
        {
            "rows": rows,
            "substeps": args.substeps,
            "waypoints": N_WAYPOINTS,
            "marker_evals_per_s_at_1024": at_1024,
        },
    )


if __name__ == "__main__":
    main()
