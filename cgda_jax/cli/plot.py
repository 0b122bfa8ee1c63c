"""``cgda plot FOLDER``: redraw the figures (and the robot's video) of a results
folder from what it stores. Argument parsing and messages only; the figures are
`cgda_jax.experiment.figures`, reading the folder `cgda_jax.experiment.load`."""

from __future__ import annotations

import pathlib

from cgda_jax.cli.output import Session, say

PLOT_EXAMPLES = """\
examples:
  cgda plot results/clean_ie                 # redraw into results/clean_ie/plots
  cgda plot results/clean_ie --out /tmp/figs # somewhere else
  cgda plot results/demo                     # every experiment of a `cgda demo`
  cgda plot results/clean_ie --no-render     # figures only, no video

Redraws the figures of a results folder from what it stores (config.toml,
result.json, arrays.npz): the PNGs, and for an execution that was rendered the
robot's video (plots/execution.mp4 and .gif, 640x480) and frame strip. Into the
folder's own plots/, report.md is rewritten to show them. In Python:
`cgda_jax.load_run(folder)`. Exit status: 0 done, 2 not a results folder (or
--out not writable), 3 any other failure.
"""


def add_plot_parser(sub, fmt) -> None:
    """The ``plot`` sub-command on the ``cgda`` parser's sub-parsers ``sub``."""
    plot = sub.add_parser(
        "plot", help="redraw the figures (and video) of a results folder",
        description="Redraw the figures of a results folder.", epilog=PLOT_EXAMPLES,
        formatter_class=fmt,
    )
    plot.add_argument("folder", help="a results folder (of `cgda run` or `cgda demo`)")
    plot.add_argument("--out", metavar="DIR",
                      help="write the figures here (default: FOLDER/plots)")
    plot.add_argument("--no-render", action="store_true",
                      help="figures only: do not render the robot's video and frames")
    plot.add_argument("--quiet", action="store_true", help="print nothing on success")
    plot.add_argument("--no-cache", action="store_true",
                      help="do not use the persistent JAX compilation cache")


def _plot_one(folder: pathlib.Path, out: pathlib.Path | None, args,
              session: Session) -> list:
    from cgda_jax.experiment.figures import draw_figures, render_run
    from cgda_jax.experiment.load import load_run
    from cgda_jax.experiment.report import report_markdown
    from cgda_jax.results_folder.rules import check_writable

    run = load_run(folder)
    own = out is None
    out = run.folder / "plots" if own else out
    check_writable(out, f"plots folder {out}")
    written = draw_figures(run, out)
    render = run.result.get("render")
    if render is not None and not args.no_render and run.kind == "execution":
        render = render_run(run, out)
        if render["ok"]:
            written += [out / "frames.png", out / "execution.mp4", out / "execution.gif"]
    if own:
        result = dict(run.result, render=render) if render is not None else run.result
        plots = sorted(str(p.relative_to(run.folder)) for p in written
                       if p.suffix == ".png")
        report = report_markdown(run.config, result, plots)
        (run.folder / "report.md").write_text(report)
    say(session, f"[{run.name}] {len(written)} files -> {out}")
    return written


def cmd_plot(args, session: Session) -> int:
    """Redraw one results folder, or each experiment of a ``cgda demo`` folder;
    0 when done (errors are raised and reported by `cgda_jax.cli`)."""
    from cgda_jax.experiment.load import REQUIRED
    from cgda_jax.results_folder.rules import MARKER, expand

    folder = expand(args.folder)
    out = expand(args.out) if args.out else None
    subs = []
    if folder.is_dir() and not (folder / "config.toml").is_file() and (
            folder / MARKER).is_file():  # a `cgda demo` folder: one per experiment
        subs = sorted(p for p in folder.iterdir()
                      if p.is_dir() and all((p / f).is_file() for f in REQUIRED))
    if subs:
        for sub in subs:
            _plot_one(sub, None if out is None else out / sub.name, args, session)
    else:
        _plot_one(folder, out, args, session)
    return 0
