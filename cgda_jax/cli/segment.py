"""``cgda segment RECORDING --library DIR --out DIR``: the actions in one long
recording. Argument parsing, files and messages only; the search is
`cgda_jax.segmentation`."""

from __future__ import annotations

import csv
import pathlib

from cgda_jax.cli.output import EXIT_MET, Session, say

SEGMENT_EXAMPLES = """\
examples:
  cgda segment task.csv --library demos/ --out task-segments/
  cgda segment task.csv --library demos/ --durations 2,15 --step 0.1 --out seg/

RECORDING is a CSV file (the format load_csv reads and `cgda track` writes: time
in seconds, then the features). The library is a folder with one sub-folder per
action, named for it, holding that action's demonstrations as CSV files with the
recording's features; each action is generalized from them (--interval-s). Writes
OUT/segments.csv (action, start_s, end_s, cost) and OUT/segments.png (the
recording's features with the recognized actions shaded and named) and prints the
table. Exit status: 0 done, 2 bad input (a missing file, an empty library folder,
features that differ from the library's), 3 any other failure.
"""


def add_segment_parser(sub, fmt) -> None:
    """The ``segment`` sub-command on the ``cgda`` parser's sub-parsers ``sub``."""
    p = sub.add_parser(
        "segment", help="split one long recording into the library's actions "
        "(a table and a figure)", description="Find the sequence of library "
        "actions (with or without pauses) in one recording.",
        epilog=SEGMENT_EXAMPLES, formatter_class=fmt)
    p.add_argument("recording", metavar="RECORDING", help="the recording (CSV)")
    p.add_argument("--library", required=True, metavar="DIR",
                   help="folder of action folders of demonstration CSV files")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for segments.csv and segments.png (created)")
    p.add_argument("--interval-s", type=float, default=1.0, metavar="S",
                   help="generalization interval of the actions (default 1 s)")
    p.add_argument("--metric", default="dtw", choices=("dtw", "dtw_multi", "euclidean"),
                   help="segment-to-action cost (default dtw, the paper's)")
    p.add_argument("--step", type=float, metavar="S",
                   help="grid step: the precision of the boundaries (default the "
                   "recording's duration / 200)")
    p.add_argument("--durations", metavar="MIN,MAX",
                   help="shortest and longest action in seconds (default 4 steps "
                   "to the whole recording; a close range is faster)")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")


def _durations(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        lo, hi = (float(v) for v in parts)
    except ValueError:
        raise ValueError(
            f"--durations must be MIN,MAX in seconds, got {text!r}") from None
    return lo, hi


def _library(folder: pathlib.Path, interval_s: float):
    from cgda_jax.data import load_csv
    from cgda_jax.recognition import ActionLibrary

    if not folder.is_dir():
        raise NotADirectoryError(f"--library {folder} is not a folder")
    demos = {}
    for action in sorted(p for p in folder.iterdir() if p.is_dir()):
        files = sorted(action.glob("*.csv"))
        if files:
            demos[action.name] = [load_csv(f) for f in files]
    if not demos:
        raise ValueError(f"--library {folder} has no action folders of CSV "
                         "demonstrations (DIR/ACTION/*.csv)")
    return ActionLibrary.from_demonstrations(demos, interval_s=interval_s)


def cmd_segment(args, session: Session) -> int:
    from cgda_jax.data import load_csv
    from cgda_jax.plotting import plot_segmentation
    from cgda_jax.segmentation import segment

    durations = _durations(args.durations)
    recording = load_csv(pathlib.Path(args.recording).expanduser())
    library = _library(pathlib.Path(args.library).expanduser(), args.interval_s)
    out = pathlib.Path(args.out).expanduser()
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out {out} is a file, not a folder")
    segments = segment(recording, library, metric=args.metric, step_s=args.step,
                       durations_s=durations)
    out.mkdir(parents=True, exist_ok=True)
    table = out / "segments.csv"
    with open(table, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["action", "start_s", "end_s", "cost"])
        for s in segments:
            w.writerow([s.action, f"{s.start:.3f}", f"{s.end:.3f}", f"{s.cost:.6g}"])
    figure = out / "segments.png"
    plot_segmentation(recording, segments, path=figure)
    if not session.quiet:
        print(f"{'action':<12} {'start [s]':>9} {'end [s]':>9} {'cost':>10}")
        for s in segments:
            print(f"{s.action:<12} {s.start:9.2f} {s.end:9.2f} {s.cost:10.4g}")
    say(session, f"[segment] {recording.name}: {len(segments)} actions -> {table}, "
        f"{figure}")
    return EXIT_MET
