"""``cgda demo``: the main job (recognition tables, clean IE and paint IET on TEO)
in one results folder, with a summary report on top. Each experiment's figures and
video are drawn in a second thread while the next experiment computes."""

from __future__ import annotations

import json
import os
import pathlib
import time
from concurrent.futures import Future, ThreadPoolExecutor

from cgda_jax.cli.output import EXIT_MET, EXIT_NOT_MET, Session, say, say_chosen
from cgda_jax.cli.run import start_one


DEMO_EXAMPLES = """\
examples:
  cgda demo                      # everything, results in results/demo/ (then -2, ...)
  cgda demo --small --out /tmp/d # a quicker check

Runs the paper's recognition tables (all features, spatial, arm points) and two
executions on the simulated TEO: clean (IE) and paint (IET). Open
<out>/report.md: a summary table, then one section per experiment. The first run
compiles (tens of seconds); later runs reuse the compilation cache.
"""


def summary_table(results: dict[str, dict]) -> list[str]:
    """Markdown rows: experiment, result, key figure, its computing time and its
    outputs' (figures, video: drawn while the next experiment computes, so the
    outputs column overlaps the next row's computing) (demo report head)."""
    rows = ["| experiment | result | key figure | computing | figures, video |",
            "|---|---|---|---|---|"]
    for name, r in results.items():
        verdict = "ok" if r.get("success") else "**NOT met**"
        if r.get("kind") == "recognition":
            key = (f"accuracy {r['accuracy']:.0%} "
                   f"({len(r['features'])} features, {r['metric']})")
        else:
            u = f" {r['error_unit']}" if r.get("error_unit") else ""
            key = (f"{r['strategy'].upper()}: max point error {r['max_point_error']:.3g}"
                   f"{u} (tolerance {r['tolerance']:.3g}{u}), {r['points']} points, "
                   f"{r['generations']} generations")
        compute = r.get("compute_s", r.get("total_time_s", r.get("wall_time_s", 0.0)))
        rows.append(f"| [{name}](#{name}) | {verdict} | {key} | {compute:.1f} s | "
                    f"{r.get('outputs_s', 0.0):.1f} s |")
    return rows


def total_line(results: dict[str, dict], wall: float, success: bool) -> str:
    """The demo report's first line: the total and how the table's times make it
    up (each experiment's figures and video drawn in a second thread while the next
    one computes: the outputs overlap, the computing times add up)."""
    compute = sum(r.get("compute_s", 0.0) for r in results.values())
    outputs = sum(r.get("outputs_s", 0.0) for r in results.values())
    return (f"Overall: {'success' if success else 'NOT all goals met'}; "
            f"{wall:.1f} s in total: {compute:.1f} s computing (the experiments one "
            f"after another, as their progress lines say) and {outputs:.1f} s of "
            "figures and videos, drawn in a second thread while the next experiment "
            f"computes (only the last one's adds to the total).")


def demoted(report: str, name: str) -> str:
    """An experiment's ``report.md`` as a section of the demo report: every heading
    one level down (its title ``## name``, its sections ``### Feasibility``...),
    its plots' paths under ``name/``."""
    lines = [("#" + line) if line.startswith("#") else line
             for line in report.replace("](plots/", f"]({name}/plots/").splitlines()]
    return "\n".join(lines) + "\n"


def _offscreen_thread_ok() -> bool:
    """Whether the robot's video may be rendered outside the main thread: EGL and
    OSMesa contexts may, GLFW's (a display, macOS) must stay on the main thread."""
    from cgda_jax.sim import headless_backends

    gl = os.environ.get("MUJOCO_GL", "").lower()
    return gl in ("egl", "osmesa") or (not gl and bool(headless_backends()))


def _done(value) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


def cmd_demo(args, session: Session) -> int:
    from cgda_jax.experiment import RunFolder, check_and_build, demo_configs

    configs = demo_configs(small=args.small)
    # each run uses its own; checked two at a time (the pair cullings' programs
    # compile side by side), the first bad config's error raised as in turn
    pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="cgda-check")
    try:
        checks = [pool.submit(check_and_build, cfg) for cfg in configs]
        built = [check.result()[1] for check in checks]
    finally:  # an error: the checks not started are dropped
        pool.shutdown(wait=True, cancel_futures=True)
    t0 = time.perf_counter()
    results = {}
    target = pathlib.Path(args.out or "results/demo").expanduser()
    with RunFolder(target, overwrite=args.overwrite, fresh=args.out is None) as rf:
        session.run_folder = rf
        say_chosen(session, "demo", rf)
        out = rf.work
        # one experiment's figures and video are drawn in a second thread while the
        # next one computes (XLA compiles and runs without the GIL)
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cgda-outputs")
        in_thread = _offscreen_thread_ok()  # (looks for the GL libraries: once)
        try:
            drawn = []
            for cfg, objects in zip(configs, built):
                pending = start_one(cfg, rf.path / cfg.name, out / cfg.name, session,
                                    objects)
                drawn.append(pool.submit(pending.finish) if in_thread
                             else _done(pending.finish()))
            for cfg, future in zip(configs, drawn):
                results[cfg.name] = future.result()
        finally:  # on an error or a signal: no drawing left running into the folder
            pool.shutdown(wait=True, cancel_futures=True)
        wall = time.perf_counter() - t0
        success = all(r.get("success") for r in results.values())
        keys = ("success", "accuracy", "strategy", "points", "max_point_error",
                "final_fitness", "evaluations", "generations", "wall_time_s",
                "compile_time_s", "total_time_s", "compute_s", "outputs_s", "render",
                "plots")
        summary = {
            "success": success,
            "small": args.small,
            "wall_time_s": wall,
            "experiments": {n: {k: r[k] for k in keys if k in r}
                            for n, r in results.items()},
        }
        (out / "result.json").write_text(json.dumps(summary, indent=2) + "\n")
        report = [f"# cgda demo{' (small)' if args.small else ''}", "",
                  total_line(results, wall, success), "", *summary_table(results), ""]
        for name in results:
            report.append(demoted((out / name / "report.md").read_text(), name))
        (out / "report.md").write_text("\n".join(report))
    say(session, f"demo {'succeeded' if success else 'finished, goals NOT all met'} "
               f"in {wall:.1f} s -> {rf.path / 'report.md'}")
    return EXIT_MET if success else EXIT_NOT_MET
