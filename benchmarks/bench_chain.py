"""Marker forward kinematics: folded chain (cgda_jax.sim.chain) vs mjx.kinematics.

Evaluates the marker site for a population of P candidates x N waypoints (default
1,024 x 17) on models/teo.xml (falls back to a 6-DoF test arm while the model is not
written), checks both give the same positions, and times them.

    python benchmarks/bench_chain.py [--pop 1024] [--waypoints 17] [--repeats 5]
"""

from __future__ import annotations

import argparse
import pathlib

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from _common import compile_jax, median_time, print_table, write_json
from mujoco import mjx

from cgda_jax.sim.chain import build_chain_fk

REPO = pathlib.Path(__file__).resolve().parents[1]

FALLBACK_ARM = """
<mujoco><worldbody><body name="b0" pos="0 0 0.5">
  <joint name="a0" axis="0 0 1"/><geom size="0.05"/>
  <body name="b1" pos="0 0.1 0" euler="0.2 0 0"><joint name="a1" axis="0 1 0"/>
    <geom size="0.05"/>
    <body name="b2" pos="0.3 0 0"><joint name="a2" axis="1 0 0"/><geom size="0.05"/>
      <body name="b3" pos="0.3 0 0"><joint name="a3" axis="0 1 0"/><geom size="0.05"/>
        <body name="b4" pos="0.2 0 0"><joint name="a4" axis="1 0 0"/>
          <geom size="0.05"/>
          <body name="b5" pos="0.1 0 0"><joint name="a5" axis="0 0 1"/>
            <geom size="0.05"/><site name="marker" pos="0.1 0 0"/>
</body></body></body></body></body></body></worldbody></mujoco>
"""


TEO_ARM = [
    "r_shoulder_flexion",
    "r_shoulder_abduction",
    "r_upper_arm_rotation",
    "r_elbow",
    "r_forearm_rotation",
    "r_wrist",
]


def load_arm() -> tuple[mujoco.MjModel, list[str], str, str]:
    """TEO's right arm and marker if models/teo.xml exists, else the fallback arm."""
    path = REPO / "models" / "teo.xml"
    if path.exists():
        model = mujoco.MjModel.from_xml_path(str(path))
        return model, TEO_ARM, "marker", "teo.xml right arm"
    model = mujoco.MjModel.from_xml_string(FALLBACK_ARM)
    return model, [f"a{i}" for i in range(6)], "marker", "fallback 6-DoF arm"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--pop", type=int, default=1024)
    parser.add_argument("--waypoints", type=int, default=17)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    model, names, site_name, label = load_arm()
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site_name)
    qadr = jnp.asarray(model.jnt_qposadr[joints])
    qpos0 = jnp.asarray(model.qpos0, dtype=jnp.float32)
    rng = np.random.default_rng(0)
    lo = model.jnt_range[joints, 0]
    hi = model.jnt_range[joints, 1]
    limited = model.jnt_limited[joints].astype(bool)
    lo, hi = np.where(limited, lo, -np.pi), np.where(limited, hi, np.pi)
    genes = jnp.asarray(
        rng.uniform(lo, hi, size=(args.pop, args.waypoints, len(joints))),
        dtype=jnp.float32,
    )

    fk = build_chain_fk(model, model.qpos0, joints, site)

    def chain_pop(g):
        return jax.vmap(jax.vmap(fk))(g)

    mx = mjx.put_model(model)
    d0 = mjx.make_data(mx)

    def mjx_one(g):
        d = d0.replace(qpos=qpos0.at[qadr].set(g))
        return mjx.kinematics(mx, d).site_xpos[site]

    def mjx_pop(g):
        return jax.vmap(jax.vmap(mjx_one))(g)

    rows = []
    outs = {}
    for name, fn in [("chain (ours)", chain_pop), ("mjx.kinematics", mjx_pop)]:
        compiled, t_compile = compile_jax(fn, genes)
        outs[name] = np.asarray(compiled(genes))
        t = median_time(lambda: compiled(genes), repeats=args.repeats)
        evals = args.pop * args.waypoints
        rows.append(
            {
                "method": name,
                "compile_s": t_compile,
                "run_s": t,
                "marker_evals_per_s": evals / t,
            }
        )
    err = float(np.max(np.abs(outs["chain (ours)"] - outs["mjx.kinematics"])))
    speedup = rows[1]["run_s"] / rows[0]["run_s"]
    print(f"model: {label}, DoF {len(joints)}, P={args.pop}, N={args.waypoints}")
    print_table(rows, ["method", "compile_s", "run_s", "marker_evals_per_s"])
    print(f"chain / mjx speed-up: {speedup:.1f}x; max |difference| = {err:.2e} m")
    write_json(
        "bench_chain",
        {
            "model": label,
            "dof": len(joints),
            "population": args.pop,
            "waypoints": args.waypoints,
            "rows": rows,
            "speedup_chain_over_mjx": speedup,
            "max_abs_difference_m": err,
        },
    )


if __name__ == "__main__":
    main()
