"""Feature selection on the real TEO recordings: cgda_jax.select_features (every
ordered pair and feature in one jitted call) vs the authors' loop over pairs and
features with dtw-python's compiled DTW (symmetric1, cityblock, / (N + M): the
recursion of the authors' ``dtw``), on the full reduced recordings.

    CGDA_XGNITIVE_DIR=... python benchmarks/bench_select.py [--repeats 3]

Each case: the streams' per-feature DTW sums of one action (D demonstrations,
up to 1196 samples, F features); ours timed after a first call (compile apart);
the largest relative difference of the sums is printed beside the times.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time

import numpy as np
from _common import REPO, median_time, print_table, write_json

from cgda_jax.data import load_xgnitive
from cgda_jax.select import normalize, select_features

CASES = (("paint", "teo/leftArm"), ("paint", "jr3"), ("iron", "teo/rightArm"))


def peer_sums(demos) -> np.ndarray:
    """The authors' double loop over ordered pairs per feature, dtw-python's DTW."""
    from dtw import dtw

    feats = normalize(demos, "none")
    out = np.zeros(feats[0].shape[1])
    for f in range(out.size):
        for x in feats:
            for y in feats:
                d = dtw(x[:, f], y[:, f], step_pattern="symmetric1",
                        dist_method="cityblock").distance
                out[f] += d / (x.shape[0] + y.shape[0])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    root = pathlib.Path(os.environ.get("CGDA_XGNITIVE_DIR",
                                       REPO.parent / "shared" / "data" / "xgnitive"))
    rows = []
    for action, stream in CASES:
        demos = load_xgnitive(root, action, stream)
        t0 = time.perf_counter()
        first = select_features(demos).distances  # compile + run
        t_first = time.perf_counter() - t0
        t_ours = median_time(lambda: select_features(demos).distances,
                             repeats=args.repeats)
        t0 = time.perf_counter()
        ref = peer_sums(demos)
        t_peer = time.perf_counter() - t0
        rows.append({
            "case": f"{action}/{stream}",
            "demos x samples": f"{len(demos)} x {max(d.n_samples for d in demos)}",
            "features": demos[0].n_features,
            "ours_s": t_ours, "ours_first_call_s": t_first,
            "dtw-python loop_s": t_peer, "speed-up": t_peer / t_ours,
            "max_rel_diff": float(np.max(np.abs(first - ref) / np.abs(ref))),
        })
    print_table(rows, list(rows[0]))
    write_json("select", {"rows": rows})


if __name__ == "__main__":
    main()
