"""Raw execution throughput on TEO: cgda_jax's Simulator vs MuJoCo C.

Populations of P random joint trajectories (N = 17 waypoints, TEO's right arm as in
the experiments: 3 evolved joints, forearm fixed) are executed:

- kinematic mode (``substeps`` forward-kinematics sub-steps per waypoint, marker
  scene): ours (jitted vmap, chain kinematics; ``--mjx-kinematics`` adds the
  ``mjx.kinematics`` back-end) vs a Python loop over MuJoCo's C ``mj_kinematics``
  (benchmarks/peers.py `MujocoMarker`, same numbers, checked here; timed on at most
  ``--c-max`` candidates, the rate extrapolated);
- dynamic mode (position actuators, ``--physics-steps`` ``mj_step`` per waypoint):
  ours (vmapped ``mjx.step``) vs ``mujoco.rollout`` with one MjData per CPU thread
  (a framepos sensor on the marker added to a copy of the model).

Rates are candidates x waypoints per second; kinematic rows also give marker
evaluations per second (x substeps). Target (2-core CPU): kinematic execution at
P = 1,024 >= 3 million marker evaluations per second.

Known problem (jax 0.10.2, mujoco-mjx 3.17, 2-core CPU): the vmapped dynamic
execution (17 waypoints x 20 mjx.step) at P >= 512 compiles but never returns (all
threads parked on futexes, no CPU use; P = 256 runs in ~1.7 s), also with
``XLA_FLAGS=--xla_cpu_multi_thread_eigen=false``; so the dynamic default stops at
P = 256.

    python benchmarks/bench_execution.py [--pops 64 1024 16384] [--dyn-pops 64 256]
        [--physics-steps 20] [--repeats 5] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import jax
import jax.numpy as jnp
import mujoco
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
from mujoco import rollout

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


def with_marker_sensor(model: mujoco.MjModel, site: str, path) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(path))
    spec.add_sensor(
        type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname=site,
    )
    return spec.compile()


def dynamic(args, robot) -> list[dict]:
    rows = []
    sim = Simulator(
        robot, MarkerScene(), mode="dynamic", physics_steps=args.physics_steps
    )
    model = with_marker_sensor(robot.mj_model, robot.marker_site, model_path("teo.xml"))
    nthread = os.cpu_count() or 1
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    act_qadr = [
        int(model.jnt_qposadr[model.actuator_trnid[a, 0]]) for a in range(model.nu)
    ]
    d = mujoco.MjData(model)
    start = np.clip(np.zeros(robot.n_dof), robot.lower, robot.upper)
    d.qpos[:] = np.asarray(robot.qpos0)
    d.qpos[robot.qpos_adr] = start
    mujoco.mj_forward(model, d)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, d, state0, spec)
    qpos0 = np.asarray(robot.qpos0, np.float64)
    for p in args.dyn_pops:
        pop = population(robot, p)
        wp = p * N_WAYPOINTS
        print(f"dynamic P={p} mjx ...", flush=True)
        r, _ = bench_ours(sim, pop, args.repeats)
        steps = wp * args.physics_steps
        rows.append(
            {
                "mode": "dynamic",
                "P": p,
                "method": "cgda_jax mjx.step",
                **r,
                "waypoints_per_s": wp / r["time_s"],
                "steps_per_s": steps / r["time_s"],
            }
        )
        # Controls: every actuator's target = the waypoint's full posture.
        qpos = np.broadcast_to(qpos0, (p, N_WAYPOINTS, model.nq)).copy()
        qpos[..., robot.qpos_adr] = np.clip(pop, robot.lower, robot.upper)
        ctrl = np.repeat(qpos[..., act_qadr], args.physics_steps, axis=1)
        init = np.broadcast_to(state0, (p, len(state0)))

        def run_rollout(ctrl=ctrl, init=init):
            return rollout.rollout(model, datas, init, ctrl)

        print(f"dynamic P={p} mujoco.rollout ...", flush=True)
        t = median_time(run_rollout, repeats=max(1, args.repeats // 2))
        rows.append(
            {
                "mode": "dynamic",
                "P": p,
                "method": f"mujoco.rollout {nthread} thr",
                "compile_s": "",
                "time_s": t,
                "waypoints_per_s": wp / t,
                "steps_per_s": steps / t,
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pops", type=int, nargs="*", default=[64, 1024, 16384])
    parser.add_argument("--dyn-pops", type=int, nargs="*", default=[64, 256])
    parser.add_argument("--substeps", type=int, default=8)
    parser.add_argument("--physics-steps", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--c-max", type=int, default=256)
    parser.add_argument("--mjx-kinematics", action="store_true")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.pops, args.dyn_pops, args.repeats, args.c_max = [64, 1024], [64], 2, 32

    robot = Robot.from_mjcf(model_path("teo.xml"), JOINTS, "marker", FIXED)
    rows = kinematic(args, robot) + dynamic(args, robot)
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
            "steps_per_s",
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
            "physics_steps": args.physics_steps,
            "waypoints": N_WAYPOINTS,
            "marker_evals_per_s_at_1024": at_1024,
        },
    )


if __name__ == "__main__":
    main()
