"""Seconds of a run's figures (``draw_figures``) and robot video (``render_run``:
frames, MP4, GIF, frame strip), per run of a results folder, in one process.

Reads a folder of runs (e.g. one written by ``cgda demo --out FOLDER``), builds
each execution run's simulator once (the run passes its own), draws everything
once to warm up (imports, fonts, the GL context, the paint wall's JAX ops), then
reports the median of ``--repeats`` per run and phase, written into a temporary
folder. Target (issue 14, 2-core CPU): both phases for the whole demo <= 5 s.

    python benchmarks/bench_figures.py FOLDER [--repeats 3]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import tempfile
import time

from _common import print_table, report_target, write_json

TARGET_S = 5.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=pathlib.Path, help="a folder of run folders")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    from cgda_jax.experiment.figures import draw_figures, render_run
    from cgda_jax.experiment.load import load_run

    folders = sorted(d for d in args.folder.iterdir() if (d / "result.json").exists())
    if not folders:
        sys.exit(f"no run folders in {args.folder} (write some: cgda demo --out DIR)")
    runs = [load_run(d) for d in folders]
    sims = {r.name: r.simulator() for r in runs if r.kind == "execution"}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for run in runs:
            out = pathlib.Path(tmp) / run.name
            phases = {"draw_figures": lambda r=run, o=out: draw_figures(r, o)}
            if run.kind == "execution":
                phases["render_run"] = lambda r=run, o=out: render_run(
                    r, o, sims[r.name])
            for phase, fn in phases.items():
                fn()  # warm-up
                times = []
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    fn()
                    times.append(time.perf_counter() - t0)
                rows.append({"run": run.name, "phase": phase,
                             "median_s": statistics.median(times),
                             "times_s": times})
    total = {p: sum(r["median_s"] for r in rows if r["phase"] == p)
             for p in ("draw_figures", "render_run")}
    rows += [{"run": "(all)", "phase": p, "median_s": s} for p, s in total.items()]
    print_table(rows, ["run", "phase", "median_s"])
    both = sum(total.values())
    report_target(f"draw_figures + render_run, all runs <= {TARGET_S:g} s", both,
                  both <= TARGET_S)
    write_json("bench_figures", {"folder": str(args.folder), "repeats": args.repeats,
                                 "rows": rows, "total_s": both})


if __name__ == "__main__":
    main()
