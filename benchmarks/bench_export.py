"""Exporting a result as a controller's trajectory (issue 22): the time
parameterization of a 17-waypoint TEO paint trajectory (target: under 1 s) with each
profile (the run's own minimum-jerk ramp, the default, and ruckig's), its JSON file,
and the replay of that file on MuJoCo C.

The waypoints are random postures within the joint limits, 10 degrees at most from
the previous one (a paint-like trajectory); the replay's features are compared with
the simulator's own execution of the same waypoints.

    python bench_export.py [--repeats 5] [--experiments paint_iet paint_iet_dynamic]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from _common import machine, median_time, print_table, write_json  # noqa: E402

from cgda_jax.builtin import experiment_path  # noqa: E402
from cgda_jax.experiment import load_config  # noqa: E402
from cgda_jax.experiment.build import build_simulator  # noqa: E402
from cgda_jax.reality.control_trajectory import trajectory_of  # noqa: E402
from cgda_jax.reality.files import load_trajectory, save_trajectory  # noqa: E402
from cgda_jax.reality.replay import replay_trajectory  # noqa: E402


def waypoints(sim, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(sim.lower, np.float64), np.asarray(sim.upper, np.float64)
    q = np.asarray(sim.robot.start_genes, np.float64)
    out = []
    for _ in range(n):
        q = np.clip(q + rng.uniform(-1, 1, q.shape) * np.deg2rad(10), lo, hi)
        out.append(q)
    return np.asarray(out, np.float32)


def bench(name: str, repeats: int, profile: str) -> dict:
    cfg = load_config(experiment_path(name))
    sim = build_simulator(cfg, 1.0)
    joints = waypoints(sim, 17, 0)
    t_export = median_time(lambda: trajectory_of(sim, joints, profile=profile),
                           repeats)
    traj = trajectory_of(sim, joints, profile=profile)
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "t.json"
        t0 = time.perf_counter()
        save_trajectory(traj, path)
        t_write = time.perf_counter() - t0
        size = path.stat().st_size
        back = load_trajectory(path)
    t0 = time.perf_counter()
    feats = replay_trajectory(sim, back)
    t_replay = time.perf_counter() - t0
    want = np.asarray(sim.execute(joints), np.float64)
    return {"experiment": name, "profile": profile, "mode": sim.mode,
            "waypoints": len(joints),
            "samples": traj.n_samples, "duration_s": round(traj.duration, 2),
            "export_s": t_export, "json_write_s": t_write, "json_kB": size / 1e3,
            "replay_s": t_replay, "peak_speed": float(np.abs(traj.qd).max()),
            "max_feature_difference": float(np.abs(feats - want).max()),
            "largest_feature": float(np.abs(want).max())}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--experiments", nargs="+",
                   default=["paint_iet", "paint_iet_dynamic"])
    args = p.parse_args()
    rows = [bench(e, args.repeats, prof) for e in args.experiments
            for prof in ("min_jerk", "ruckig")]
    print_table(rows, list(rows[0]))
    write_json("export", {"machine": machine(), "rows": rows})
    print(json.dumps(machine()))


if __name__ == "__main__":
    main()
