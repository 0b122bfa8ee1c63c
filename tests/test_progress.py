"""Progress display: whole lines off a terminal, a tqdm bar on a terminal."""

import io

from cgda_jax.progress import ProgressLine


class _Tty(io.StringIO):
    def isatty(self):
        return True


def _updates(bar, n, done_last=True):
    for g in range(1, n + 1):
        bar({"generations": 10 * g, "points_done": g, "worst_error": 1.0 / g,
             "elapsed_s": 0.0, "done": done_last and g == n})


def test_non_tty_writes_whole_lines_first_and_last_only():
    s = io.StringIO()
    bar = ProgressLine("clean", total_points=5, stream=s, interval_s=1e9)
    _updates(bar, 5)
    bar.close()
    lines = s.getvalue().splitlines(keepends=True)
    assert "\r" not in s.getvalue()
    assert len(lines) == 2 and all(x.endswith("\n") for x in lines)
    assert lines[0].startswith("[clean] gen 10 | done 1/5")
    assert lines[1].startswith("[clean] gen 50 | done 5/5 | worst 0.2")


def test_non_tty_close_writes_the_last_line_of_an_unfinished_run():
    s = io.StringIO()
    bar = ProgressLine("x", stream=s, interval_s=1e9)
    _updates(bar, 3, done_last=False)
    bar.close()
    assert [x.split(" |")[0] for x in s.getvalue().splitlines()] == ["[x] gen 10", "[x] gen 30"]
    s2 = io.StringIO()
    bar = ProgressLine("x", stream=s2, interval_s=0.0)  # no throttling: every update
    _updates(bar, 3)
    assert len(s2.getvalue().splitlines()) == 3


def test_tty_shows_a_tqdm_bar_over_the_points_and_ends_it():
    s = _Tty()
    bar = ProgressLine("x", total_points=9, stream=s)
    _updates(bar, 3, done_last=False)
    text = s.getvalue()
    assert "\n" not in text and text.count("\r") >= 3  # redrawn in place
    last = text.split("\r")[-1]
    assert last.startswith("[x] 3/9 points |") and "gen 30 | worst 0.3333 |" in last
    bar.message("note")  # printed above the bar, which stays
    assert "note\n" in s.getvalue() and bar.bar is not None
    _updates(bar, 1)  # done: the bar is closed, its line ended
    assert s.getvalue().endswith("\n") and bar.bar is None
    assert s.getvalue().rstrip().split("\r")[-1].startswith("[x] 1/9 points")


def test_tty_bar_takes_its_total_from_the_updates():
    s = _Tty()
    bar = ProgressLine("x", stream=s)
    bar({"generations": 5, "points_done": 2, "points": 11, "done": False})
    assert s.getvalue().split("\r")[-1].startswith("[x] 2/11 points |")
    bar.close()
    assert s.getvalue().endswith("\n") and bar.bar is None


def test_time_is_split_into_setup_and_run_when_known():
    s = io.StringIO()
    bar = ProgressLine("x", stream=s)
    bar({"generations": 10, "elapsed_s": 0.0, "done": True})
    assert "run 0.0 s (setup+compile " in s.getvalue()
    s = io.StringIO()
    ProgressLine("x", stream=s)({"generations": 10, "done": True})
    assert "setup" not in s.getvalue() and s.getvalue().rstrip().endswith(" s")
    quiet = io.StringIO()
    bar = ProgressLine("x", stream=quiet, quiet=True)
    _updates(bar, 2)
    bar.close()
    assert quiet.getvalue() == ""


def test_bar_is_drawn_on_a_terminal_without_a_size(monkeypatch):
    """stderr a pty of 0 x 0 (e.g. under `script`): tqdm alone would draw nothing."""
    import os
    import pty
    import select
    import sys

    master, slave = pty.openpty()
    try:
        with open(slave, "w", closefd=False) as stream:
            assert stream.isatty()
            monkeypatch.setattr(sys, "stderr", stream)  # tqdm sizes only std streams
            bar = ProgressLine("x", total_points=2)
            bar({"generations": 3, "points_done": 2, "done": True})
        data = b""
        while select.select([master], [], [], 0.5)[0]:
            data += os.read(master, 4096)
    finally:
        os.close(master)
        os.close(slave)
    assert b"[x] 2/2 points |" in data and b"gen 3" in data
