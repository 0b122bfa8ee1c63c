"""DTW: cgda_jax.dtw (vmapped, jitted) vs dtaidistance (C), dtw-python and tslearn.

All compute the paper's per-dimension score (|.| local cost, D(N,M)/(N+M), summed
over features; see peers.py for the settings that make each peer do so), checked
here on every case. Cases:

- P = 1,024 candidates of length T in {20, 100} with F in {3, 8} features against
  one reference of the same length (the fitness of one generation);
- a 28 x 4 recognition matrix of length-300, 8-feature trajectories.

    python benchmarks/bench_dtw.py [--repeats 5] [--quick] [--no-slow-peers]

``--quick`` runs only the smallest case (a smoke test). Pure-Python-loop peers
(dtw-python, tslearn) are timed with one repeat when one call takes over 2 s.
Target (2-core CPU): ours >= 2x faster than dtaidistance's parallel C on
1,024 x 100 x 3.
"""

from __future__ import annotations

import argparse
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

from cgda_jax.distance import dtw

TARGET_RATIO = 2.0  # ours vs dtaidistance parallel C, 1,024 x 100 x 3


def to_ref(cands, ref):
    return jax.vmap(dtw, in_axes=(0, None))(cands, ref)


def matrix(queries, refs):
    return jax.vmap(jax.vmap(dtw, in_axes=(None, 0)), in_axes=(0, None))(queries, refs)


def timed_peer(fn, repeats: int) -> tuple[float, np.ndarray]:
    """(median seconds, result) with fewer repeats for slow peers."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    if first > 2.0:
        return first, out
    return median_time(fn, repeats=repeats, warmup=0), out


def run_case(name, queries, refs, repeats, slow_peers) -> list[dict]:
    """Time every method on (Q, T, F) queries vs (R, T, F) refs."""
    single = refs.shape[0] == 1
    q32, r32 = jnp.asarray(queries, jnp.float32), jnp.asarray(refs, jnp.float32)
    if single:
        fn, args = to_ref, (q32, r32[0])
    else:
        fn, args = matrix, (q32, r32)
    compiled, t_compile = compile_jax(fn, *args)
    ours = np.asarray(compiled(*args)).reshape(len(queries), -1)
    t_ours = median_time(lambda: compiled(*args), repeats=repeats)
    pairs = queries.shape[0] * refs.shape[0]
    rows = [
        {
            "case": name,
            "method": "cgda_jax (jit+vmap)",
            "time_s": t_ours,
            "compile_s": t_compile,
            "pairs_per_s": pairs / t_ours,
            "max_rel_err": 0.0,
        }
    ]

    def add(method, fn):
        t, out = timed_peer(fn, repeats)
        out = np.asarray(out).reshape(ours.shape)
        rows.append(
            {
                "case": name,
                "method": method,
                "time_s": t,
                "compile_s": "",
                "pairs_per_s": pairs / t,
                "ratio_peer_over_ours": t / t_ours,
                "max_rel_err": float(np.max(np.abs(out - ours) / np.abs(out))),
            }
        )

    q64, r64 = queries.astype(np.float64), refs.astype(np.float64)
    add("dtaidistance C parallel", lambda: peers.dtai_block(q64, r64, parallel=True))
    add("dtaidistance C serial", lambda: peers.dtai_block(q64, r64, parallel=False))
    if slow_peers:
        add(
            "dtw-python (loop)",
            lambda: peers.pairs_matrix(peers.dtwpython_pair, q64, r64),
        )
        try:
            import tslearn  # noqa: F401

            peers.tslearn_pair(q64[0], r64[0])  # numba compile, not timed
            add(
                "tslearn (loop)",
                lambda: peers.pairs_matrix(peers.tslearn_pair, q64, r64),
            )
        except ImportError:
            print("tslearn not installed; skipped")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-slow-peers", action="store_true")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    cases = []
    shapes = [(20, 3)] if args.quick else [(20, 3), (20, 8), (100, 3), (100, 8)]
    for t, f in shapes:
        ref = np.cumsum(rng.normal(size=(1, t, f)), axis=1).astype(np.float32)
        cands = ref + 0.3 * rng.normal(size=(1024, t, f)).astype(np.float32)
        cases.append((f"1024 x {t} x {f} vs 1", cands, ref))
    if not args.quick:
        lib = np.cumsum(rng.normal(size=(4, 300, 8)), axis=1).astype(np.float32)
        queries = lib[rng.integers(0, 4, 28)] + 0.3 * rng.normal(size=(28, 300, 8))
        cases.append(("28 x 4 matrix, 300 x 8", queries.astype(np.float32), lib))

    rows = []
    for name, q, r in cases:
        print(f"case {name} ...", flush=True)
        rows += run_case(name, q, r, args.repeats, not args.no_slow_peers)
    cols = ["case", "method", "time_s", "compile_s", "pairs_per_s"]
    print_table(rows, cols + ["ratio_peer_over_ours", "max_rel_err"])

    row = find_row(rows, case="1024 x 100 x 3 vs 1", method="dtaidistance C parallel")
    target = None if row is None else row["ratio_peer_over_ours"]
    report_target(
        f">= {TARGET_RATIO}x dtaidistance parallel C at 1024x100x3 (ratio)",
        target,
        target is not None and target >= TARGET_RATIO,
    )
    write_json(
        "bench_dtw",
        {
            "rows": rows,
            "target_ratio": TARGET_RATIO,
            "ratio_vs_dtaidistance_parallel": target,
        },
    )


if __name__ == "__main__":
    main()
