"""``cgda track VIDEO... --out DEMOS/``: demonstrations from a camera. Argument
parsing and messages only; the tracking is `cgda_jax.vision`."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import sys
import tempfile

from cgda_jax.cli.output import EXIT_FAILURE, EXIT_MET, Session, say

TRACK_EXAMPLES = """\
examples:
  cgda track demo1.mp4 demo2.mp4 --out demos/          # colour picked automatically
  cgda track clip.mp4 --color 40-80,100,50 --out demos/ # hue 40-80, S >= 100, V >= 50
  cgda track rgb/ --depth depth/ --intrinsics cam.json --out demos/
  cgda track recordings/MOVE-* --out demos/             # recording folders

VIDEO is a video file (anything OpenCV reads), a folder of frames (PNG/JPEG, in
name order), or a recording folder (rgb/, and depth/, intrinsics.json,
recording.json when present: what cgda_jax.vision.record writes). For each VIDEO,
DEMOS/NAME.csv (the format load_csv reads: time, then features with their units in
the names), DEMOS/NAME_colors.csv (the colour range used in each frame) and
DEMOS/NAME_sheet.png (a contact sheet to check the track by eye).
The object is the largest region in the colour range (OpenCV HSV: hue 0-180,
saturation and value 0-255), or, with --color auto (the default), the first frame's
most saturated region, followed as its colour changes, its faces turn into shade and
the light moves or dims (the range learned again every frame). A lost object is
interpolated over gaps of up to --max-gap frames; a longer gap refuses the video.
Every video is tracked before any file is written, and the files are written aside
and moved in: all of them, or none (a folder made for them is removed again).
Exit status: 0 done, 2 bad input (a file that cannot be read, no object in range,
a gap too long, --fps outside 0.001-100000, --max-gap < 0, --min-area < 1, --out
a file or not writable), 3 any other failure (a full disk: nothing written).
"""


def add_track_parser(sub, fmt) -> None:
    """The ``track`` sub-command on the ``cgda`` parser's sub-parsers ``sub``."""
    p = sub.add_parser(
        "track", help="demonstrations from a camera: track a coloured object in "
        "videos into CSV files", description="Track one coloured object in each "
        "video and write its features as a demonstration.", epilog=TRACK_EXAMPLES,
        formatter_class=fmt,
    )
    p.add_argument("videos", nargs="+", metavar="VIDEO",
                   help="video file, frame folder or recording folder")
    p.add_argument("--out", required=True, metavar="DEMOS",
                   help="folder for the CSV files and contact sheets (created)")
    p.add_argument("--depth", action="append", default=[], metavar="DIR",
                   help="folder of depth frames aligned with the video (16-bit PNG "
                   "or .npy); once per VIDEO, in order")
    p.add_argument("--intrinsics", metavar="FILE",
                   help="camera intrinsics JSON (needed with --depth; replaces a "
                   "recording folder's own, e.g. to add a camera_to_world pose)")
    p.add_argument("--color", default="auto", metavar="RANGE",
                   help="HLO-HHI[,SMIN,VMIN] in OpenCV HSV, or auto (default)")
    p.add_argument("--fps", type=float,
                   help="frame rate (default: the video's, a recording's, else 30)")
    p.add_argument("--max-gap", type=int, default=5, metavar="N",
                   help="longest run of lost frames that is interpolated (default 5)")
    p.add_argument("--min-area", type=int, default=30, metavar="PX",
                   help="smallest region that counts as the object (default 30 px)")
    p.add_argument("--no-depth", action="store_true",
                   help="ignore a recording folder's depth frames")
    p.add_argument("--no-sheet", action="store_true", help="no contact sheets")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")


def _recording(path: pathlib.Path, args) -> dict:
    """Where a VIDEO's frames, depth, intrinsics and fps come from."""
    if path.is_dir() and (path / "rgb").is_dir():
        meta = path / "recording.json"
        fps = json.loads(meta.read_text()).get("fps") if meta.is_file() else None
        depth = path / "depth"
        intr = path / "intrinsics.json"
        return {"video": path / "rgb", "name": path.name,
                "depth": depth if depth.is_dir() and not args.no_depth else None,
                "intrinsics": args.intrinsics or (intr if intr.is_file() else None),
                "fps": args.fps if args.fps is not None else fps}
    name = path.stem if path.is_file() else path.name
    return {"video": path, "name": name, "depth": None, "intrinsics": args.intrinsics,
            "fps": args.fps}


def _jobs(args) -> list[dict]:
    paths = [pathlib.Path(v).expanduser() for v in args.videos]
    jobs = [_recording(p, args) for p in paths]
    if args.depth:
        if len(args.depth) != len(jobs):
            raise ValueError(f"--depth given {len(args.depth)} time(s) for "
                             f"{len(jobs)} video(s): give it once per video")
        for job, d in zip(jobs, args.depth):
            job["depth"] = pathlib.Path(d).expanduser()
    names = [j["name"] for j in jobs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"videos with the same name {dup} would write the same "
                         "CSV file; track them into different --out folders")
    return jobs


def cmd_track(args, session: Session) -> int:
    from cgda_jax.vision.cv import cv2

    try:
        cv2()
    except ImportError as err:
        print(f"cgda: error: {err}", file=sys.stderr)
        return EXIT_FAILURE
    from cgda_jax.data import save_csv
    from cgda_jax.results_folder.rules import check_writable
    from cgda_jax.vision import contact_sheet, track_video

    jobs = _jobs(args)
    out = pathlib.Path(args.out).expanduser()
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out {out} is a file, not a folder")
    check_writable(out, f"--out {out}")
    tracks = [track_video(job["video"], depth=job["depth"],
                          intrinsics=job["intrinsics"], color=args.color,
                          fps=job["fps"], max_gap=args.max_gap,
                          min_area=args.min_area, name=job["name"])
              for job in jobs]  # every video tracked before any file is written
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    work = pathlib.Path(tempfile.mkdtemp(prefix=".cgda-track-", dir=out))
    try:  # all the files, or none: written aside, then moved in
        lines = []
        for job, track in zip(jobs, tracks):
            written = [work / f"{job['name']}.csv"]
            save_csv(track.demo, written[0])
            written.append(track.write_colors(work / f"{job['name']}_colors.csv"))
            if not args.no_sheet:
                written.append(contact_sheet(job["video"], track,
                                             work / f"{job['name']}_sheet.png"))
            lines.append(f"[track] {job['video']}: {track.summary()} -> "
                         + ", ".join(str(out / w.name) for w in written))
        for f in sorted(work.iterdir()):
            os.replace(f, out / f.name)
    except BaseException:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    for line in lines:
        say(session, line)
    return EXIT_MET
