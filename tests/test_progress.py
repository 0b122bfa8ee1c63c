"""Progress display: whole lines off a terminal, one rewritten line on a terminal."""

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
    assert lines[0].startswith("[clean] gen 10 | points 1/5")
    assert lines[1].startswith("[clean] gen 50 | points 5/5 | worst 0.2")


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


def test_tty_rewrites_one_line_and_ends_it():
    s = _Tty()
    bar = ProgressLine("x", stream=s)
    _updates(bar, 3, done_last=False)
    assert s.getvalue().count("\r") == 3 and "\n" not in s.getvalue()
    bar.message("note")  # ends the pending line first
    assert s.getvalue().endswith("\nnote\n")
    _updates(bar, 1)
    assert s.getvalue().endswith("\n")


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
