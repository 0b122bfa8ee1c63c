"""Dynamic (physics) execution on TEO: cgda_jax's backends vs ``mujoco.rollout``.

Populations of P random joint trajectories (N = 17 waypoints, TEO's right arm as in
the experiments: 3 evolved joints, forearm fixed at 45 deg, the other joints welded)
are executed in dynamic mode, ``--waypoint-s`` seconds per waypoint at ``--timestep``
(default 1 s at 0.01 s = 100 physics steps per waypoint, as in
experiments/clean_ie_dynamic.toml):

- ours, ``physics="mujoco"``: the jitted, vmapped ``Simulator.execute``; each
  waypoint's whole batch is one ``jax.pure_callback`` into ``mujoco.rollout``;
- ours, ``physics="mjx"``: the same program on ``mujoco.mjx`` (``lax.map`` over
  slices of 256 candidates on the CPU);
- peer: ``mujoco.rollout`` alone (one MjData per CPU thread) on the same simulated
  model with the same reference controls (minimum-jerk moves then holds, computed in
  NumPy), all 17 x 100 steps in one call: what a user would write by hand.

Rates are physics steps per second (P x N x steps / time); every row's features are
checked against the peer's (max |diff| in the note). Target: ours within 2x of the
peer at P = 256 (ratio = peer time / our time >= 0.5).

    python benchmarks/bench_dynamic.py [--pops 64 256 1024] [--mjx-pops 64 256 512]
        [--repeats 5] [--quick]
"""

from __future__ import annotations

import argparse
import math
import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from _common import compile_jax, find_row, median_time, print_table, report_target, write_json
from mujoco import rollout

from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path

JOINTS = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
FIXED = {"r_forearm_rotation": math.radians(45.0)}
N_WAYPOINTS = 17


def population(robot: Robot, p: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    return rng.uniform(lo, hi, size=(p, N_WAYPOINTS, robot.n_dof)).astype(np.float32)


def reference_controls(sim: Simulator, pop: np.ndarray) -> np.ndarray:
    """(P, N * steps, nu) controls of the minimum-jerk reference, in NumPy."""
    phys = sim.physics
    q = np.broadcast_to(phys.qpos0, (*pop.shape[:2], phys.nq)).copy()
    q[..., phys.gene_qadr] = np.clip(pop, sim.robot.lower, sim.robot.upper)
    targets = q[..., phys.act_qadr]  # (P, N, nu)
    q0 = phys.qpos0.copy()
    q0[phys.gene_qadr] = np.clip(np.zeros(sim.n_dof), sim.robot.lower, sim.robot.upper)
    prev = np.concatenate(
        [np.broadcast_to(q0[phys.act_qadr], (len(pop), 1, phys.nu)), targets[:, :-1]],
        axis=1)
    prof = np.asarray(sim._profile)[None, None, :, None]  # (1, 1, T, 1)
    ctrl = prev[:, :, None] + prof * (targets - prev)[:, :, None]
    return ctrl.reshape(len(pop), -1, phys.nu)


def peer(sim: Simulator, pop: np.ndarray, repeats: int) -> tuple[float, np.ndarray]:
    """mujoco.rollout on the same model and controls: (median s, features (P, N, 3))."""
    phys = sim.physics
    m = phys.model
    nthread = os.cpu_count() or 1
    datas = [mujoco.MjData(m) for _ in range(nthread)]
    pool = rollout.Rollout(nthread=nthread)
    ctrl = reference_controls(sim, pop)
    ctrl = np.concatenate([ctrl, ctrl[:, -1:]], axis=1)  # sensors lag one step
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    d = mujoco.MjData(m)
    d.qpos[:] = phys.qpos0
    d.qpos[phys.gene_qadr] = np.clip(np.zeros(sim.n_dof), sim.robot.lower,
                                     sim.robot.upper)
    state0 = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, state0, spec)
    init = np.tile(state0, (len(pop), 1))

    def run():
        return pool.rollout(m, datas, init, ctrl)

    t = median_time(run, repeats=repeats)
    _, sens = run()
    k = sim.physics_steps
    feats = sens[:, k::k, phys.marker_adr:phys.marker_adr + 3]  # after each waypoint
    return t, feats


def ours(sim: Simulator, pop: np.ndarray, repeats: int) -> tuple[dict, np.ndarray]:
    x = jnp.asarray(pop)
    compiled, t_compile = compile_jax(sim._execute_batched, x)
    out = np.asarray(compiled(x))
    t = median_time(lambda: compiled(x), repeats=repeats)
    return {"compile_s": t_compile, "time_s": t}, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pops", type=int, nargs="*", default=[64, 256, 1024])
    parser.add_argument("--mjx-pops", type=int, nargs="*", default=[64, 256, 512])
    parser.add_argument("--waypoint-s", type=float, default=1.0)
    parser.add_argument("--timestep", type=float, default=0.01)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.pops, args.mjx_pops, args.repeats = [64], [64], 2

    robot = Robot.from_mjcf(model_path("teo.xml"), JOINTS, "marker", FIXED)
    sims = {b: Simulator(robot, MarkerScene(), mode="dynamic", physics=b,
                         waypoint_s=args.waypoint_s, timestep=args.timestep)
            for b in ("mujoco", "mjx")}
    steps = sims["mujoco"].physics_steps
    rows = []
    for p in sorted(set(args.pops) | set(args.mjx_pops)):
        pop = population(robot, p)
        n_steps = p * N_WAYPOINTS * steps
        print(f"P={p} mujoco.rollout (peer) ...", flush=True)
        t_peer, want = peer(sims["mujoco"], pop, args.repeats)
        rows.append({"P": p, "method": "peer mujoco.rollout", "compile_s": "",
                     "time_s": t_peer, "steps_per_s": n_steps / t_peer})
        print(f"  {t_peer:.3f} s, {n_steps / t_peer:.3g} steps/s", flush=True)
        for name, sim in sims.items():
            if p not in (args.pops if name == "mujoco" else args.mjx_pops):
                continue
            print(f"P={p} cgda_jax physics={name} ...", flush=True)
            r, out = ours(sim, pop, args.repeats)
            rows.append({"P": p, "method": f"cgda_jax {name}", **r,
                         "steps_per_s": n_steps / r["time_s"],
                         "ratio": t_peer / r["time_s"],
                         "note": f"max|diff| vs peer {np.abs(out - want).max():.1e} m"})
            # as it ends, so a time-boxed run (a lent GPU) keeps its figures
            print(f"  {r['time_s']:.3f} s (compile {r['compile_s']:.1f} s), ratio "
                  f"{t_peer / r['time_s']:.2f}x, {rows[-1]['note']}", flush=True)
    print(f"TEO dynamic, {N_WAYPOINTS} waypoints x {steps} steps "
          f"(timestep {sims['mujoco'].physics.timestep:g} s), "
          f"{sims['mujoco'].physics.nq} simulated joints")
    print_table(rows, ["P", "method", "compile_s", "time_s", "steps_per_s", "ratio",
                       "note"])
    row = find_row(rows, P=256, method="cgda_jax mujoco")
    if row is not None:
        report_target("ours (physics=mujoco) within 2x of mujoco.rollout at P=256 "
                      "(peer time / ours)", row["ratio"], row["ratio"] >= 0.5)
    row = find_row(rows, P=256, method="cgda_jax mjx")
    if row is not None:
        report_target("ours (physics=mjx) within 2x of mujoco.rollout at P=256",
                      row["ratio"], row["ratio"] >= 0.5)
    write_json("bench_dynamic", {"rows": rows, "waypoints": N_WAYPOINTS,
                                 "physics_steps": steps, "timestep": args.timestep,
                                 "jax_backend": jax.default_backend()})


if __name__ == "__main__":
    main()
