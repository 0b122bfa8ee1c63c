"""Collider.path_min_distance on TEO: P candidates x K sub-steps, jitted and vmapped.

Prints, for 3 and 6 evolved right-arm joints (with and without a box obstacle), the
number of pairs, the compile time and the median of 5 timed runs (compile apart).

    PYTHONPATH=. python benchmarks/bench_collision.py [--P 64] [--K 67]
"""

import argparse
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax import Robot, model_path
from cgda_jax.sim.collision import Collider, Obstacle

JOINTS = {
    3: ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"],
    6: ["r_shoulder_flexion", "r_shoulder_abduction", "r_upper_arm_rotation",
        "r_elbow", "r_forearm_rotation", "r_wrist"],
}
BOARD = Obstacle("board", "box", (0.6, -0.5, 0.3), (0.01, 0.4, 0.4))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--P", type=int, default=64)
    ap.add_argument("--K", type=int, default=67)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"backend {jax.default_backend()}, P={args.P}, K={args.K}")
    for dof, joints in JOINTS.items():
        robot = Robot.from_mjcf(model_path("teo.xml"), joints, "marker")
        for obstacles in ((), (BOARD,)):
            col = Collider(robot, obstacles)
            rng = np.random.default_rng(0)
            paths = jnp.asarray(rng.uniform(
                np.asarray(robot.lower), np.asarray(robot.upper),
                size=(args.P, args.K, dof)).astype(np.float32))
            fn = jax.jit(jax.vmap(col.path_min_distance))
            t0 = time.perf_counter()
            compiled = fn.lower(paths).compile()
            compile_s = time.perf_counter() - t0
            jax.block_until_ready(compiled(paths))
            times = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                jax.block_until_ready(compiled(paths))
                times.append(time.perf_counter() - t0)
            med = statistics.median(times)
            n = args.P * args.K
            label = "+ box obstacle" if obstacles else "no obstacle"
            print(f"TEO {dof} joints, {label}: {col.n_pairs} pairs, compile "
                  f"{compile_s:.2f} s, run {med * 1e3:.2f} ms median "
                  f"({med / n * 1e6:.2f} us per posture)")


if __name__ == "__main__":
    main()
