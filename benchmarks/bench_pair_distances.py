"""Signed distances of one geom pair type: ours (batched, jitted) vs MuJoCo C.

For each pair type of the feasibility check (box-box, capsule-box, box-cylinder,
capsule-cylinder, capsule-capsule), N random relative poses of two geoms of TEO-like
sizes (half of them overlapping or near): ``primitive_distances.pair_distance`` with
``exact=True`` (the independent check's) and ``exact=False`` (the strategies'
check), `jax.vmap`-ed over the N poses, against a Python loop over MuJoCo C's
``mj_geomDistance`` on the same poses (the peer a user would write). Prints per type
the time per pair (median of repeats, compile apart), the ratios, and how the values
agree: separated pairs (ours exact vs MuJoCo; ``cheap_above_mm``: how far the cheap
mode ever lies above MuJoCo, 0 for a lower bound), overlapping pairs (the depth: ours
vs MuJoCo's, the shortest separating translation; ours is the deepest core point's
depth for round shapes and the exact mode's box-cylinder, so it may be shallower).

    python benchmarks/bench_pair_distances.py [--n 4096] [--repeats 15]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from _common import machine, median_time, print_table, write_json

from cgda_jax.sim import primitive_distances as df

#: MuJoCo sizes of the two geoms of each type (TEO's hand box, forearm capsule, a
#: valve wheel's cylinder).
SIZES = {
    "box": (0.05, 0.1, 0.03),
    "capsule": (0.03, 0.12, 0.0),
    "cylinder": (0.12, 0.02, 0.0),
}
PAIRS = [("box", "box"), ("capsule", "box"), ("box", "cylinder"),
         ("capsule", "cylinder"), ("capsule", "capsule")]
SECOND = {"box": (0.2, 0.02, 0.08), "capsule": (0.04, 0.2, 0.0),
          "cylinder": (0.06, 0.15, 0.0)}


def poses(kind_a: str, kind_b: str, n: int, seed: int):
    """n random poses of geoms a and b: MuJoCo's model and data, each pose's
    ``(geom_xpos, geom_xmat)`` for the peer, and our inputs (6 stacked arrays)."""
    xml = f"""<mujoco><worldbody>
      <body name="A" mocap="true"><geom type="{kind_a}" size="{' '.join(
          str(x) for x in SIZES[kind_a] if x)}"/></body>
      <body name="B" mocap="true"><geom type="{kind_b}" size="{' '.join(
          str(x) for x in SECOND[kind_b] if x)}"/></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    cols = [[] for _ in range(6)]
    frames = []
    for _ in range(n):
        for k in range(2):
            q = rng.normal(size=4)
            d.mocap_quat[k] = q / np.linalg.norm(q)
        d.mocap_pos[1] = rng.uniform(-0.25, 0.25, 3)
        mujoco.mj_kinematics(m, d)
        frames.append((d.geom_xpos.copy(), d.geom_xmat.copy()))
        for k, x in enumerate((m.geom_size[0], d.geom_xmat[0].reshape(3, 3),
                               d.geom_xpos[0], m.geom_size[1],
                               d.geom_xmat[1].reshape(3, 3), d.geom_xpos[1])):
            cols[k].append(np.array(x, np.float32))
    return m, d, frames, [jnp.asarray(np.stack(c)) for c in cols]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4096)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    rows = []
    for ka, kb in PAIRS:
        # the peer's poses are computed once: only its distances are timed
        m, d, frames, cols = poses(ka, kb, args.n, seed=0)

        def peer():
            out = np.empty(len(frames))
            for i, (xp, xm) in enumerate(frames):
                d.geom_xpos[:], d.geom_xmat[:] = xp, xm
                out[i] = mujoco.mj_geomDistance(m, d, 0, 1, 10.0, None)
            return out

        ref = peer()
        peer_s = median_time(peer, args.repeats, warmup=0)
        row = {"pair": f"{ka}-{kb}", "n": args.n,
               "overlapping": int(np.sum(ref < -1e-4)),
               "mujoco_us": 1e6 * peer_s / args.n}
        for exact in (True, False):
            fn = jax.jit(jax.vmap(lambda sa, Ra, pa, sb, Rb, pb, e=exact:
                                  df.pair_distance(*_order(ka, kb, sa, Ra, pa, sb, Rb,
                                                           pb), exact=e)))
            t0 = time.perf_counter()
            fn = fn.lower(*cols).compile()
            compile_s = time.perf_counter() - t0
            ours = np.asarray(fn(*cols))
            s = median_time(lambda: jax.block_until_ready(fn(*cols)), args.repeats)
            tag = "exact" if exact else "cheap"
            # MuJoCo's capsule-box reports a separation for a thin capsule that
            # pierces a box (tests/test_collision.py checks ours by brute force
            # there): poses whose signs disagree are counted, not compared
            agree = ~((np.abs(ref) > 1e-4) & (np.sign(ours) != np.sign(ref)))
            sep, pen = (ref > 1e-4) & agree, (ref < -1e-4) & agree
            row[f"{tag}_us"] = 1e6 * s / args.n
            row[f"{tag}_x"] = peer_s / s
            row[f"{tag}_compile_s"] = compile_s
            row[f"{tag}_signs_differ"] = int(np.sum(~agree))
            row[f"{tag}_sep_err_mm"] = 1e3 * float(np.max(np.abs(ours[sep] - ref[sep])))
            row[f"{tag}_above_mm"] = 1e3 * float(np.max((ours - ref)[agree]))
            gap = np.abs(ours[pen] - ref[pen]) if pen.any() else np.zeros(1)
            row[f"{tag}_depth_err_mm"] = 1e3 * float(np.max(gap))
            row[f"{tag}_depth_within_0.1mm"] = float(np.mean(gap < 1e-4))
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()},
              flush=True)
        rows.append(row)
    print_table(rows, ["pair", "n", "overlapping", "mujoco_us", "exact_us", "exact_x",
                       "cheap_us", "cheap_x", "exact_signs_differ", "exact_sep_err_mm",
                       "cheap_above_mm", "exact_depth_err_mm",
                       "exact_depth_within_0.1mm", "cheap_depth_err_mm",
                       "cheap_depth_within_0.1mm"])
    write_json("pair_distances", {"machine": machine(), "rows": rows})


def _order(ka, kb, sa, Ra, pa, sb, Rb, pb):
    """`pair_distance`'s arguments in its canonical order (`swap_needed`)."""
    if df.swap_needed(ka, kb):
        return kb, ka, sb, Rb, pb, sa, Ra, pa
    return ka, kb, sa, Ra, pa, sb, Rb, pb


if __name__ == "__main__":
    main()
