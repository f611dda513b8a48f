"""Progress formats farm managers parse."""

from __future__ import annotations

import io
import json
import re
import threading
from pathlib import Path

from svgf_cli.progress import Progress

DEADLINE_STOCK = re.compile(r".*Progress: (\d+)%.*")


def test_lines_match_deadline_regex_and_skip_warmup() -> None:
    out, err = io.StringIO(), io.StringIO()
    progress = Progress("auto", total=4, out=out, err=err)  # StringIO is not a tty -> lines
    assert progress.mode == "lines"
    progress.warmup(1000, 1, 2)
    progress.warmup(1001, 2, 2)
    for i, frame in enumerate(range(1002, 1006)):
        progress.frame_done(frame, 0.25 + i * 0.0)
    lines = out.getvalue().splitlines()
    assert lines[:2] == ["Warmup: 1/2 (frame 1000)", "Warmup: 2/2 (frame 1001)"]
    assert lines[2] == "Progress: 25% (frame 1002, 1/4, 0.25 s/frame)"
    percents = [int(m.group(1)) for line in lines if (m := DEADLINE_STOCK.match(line))]
    assert percents == [25, 50, 75, 100]
    assert err.getvalue() == ""


def test_json_events() -> None:
    out, err = io.StringIO(), io.StringIO()
    progress = Progress("json", total=2, out=out, err=err)
    progress.info("svgf start-up line")
    progress.warmup(1, 1, 1)
    progress.frame_done(2, 0.5)
    progress.frame_done(3, 0.5)
    progress.finish()
    events = [json.loads(line) for line in out.getvalue().splitlines()]
    assert [e["event"] for e in events] == ["warmup", "frame_done", "frame_done", "done"]
    assert events[1] == {
        "event": "frame_done",
        "frame": 2,
        "index": 1,
        "total": 2,
        "seconds": 0.5,
        "percent": 50,
    }
    # Start-up information goes to stderr so stdout stays pure JSON.
    assert "svgf start-up line" in err.getvalue()


def test_quiet_suppresses_automatic_progress_but_not_warnings() -> None:
    out, err = io.StringIO(), io.StringIO()
    progress = Progress("auto", total=1, quiet=True, out=out, err=err)
    progress.info("hello")
    progress.frame_done(1, 0.1)
    progress.warning("3 NaN values")
    assert out.getvalue() == ""
    assert err.getvalue() == "WARNING: 3 NaN values\n"


def test_bar_rewrites_one_line() -> None:
    out, err = io.StringIO(), io.StringIO()
    progress = Progress("bar", total=2, out=out, err=err)
    progress.warmup(1, 1, 1)
    progress.frame_done(2, 0.1)
    progress.warning("a warning while the bar is drawn")
    progress.frame_done(3, 0.1)
    progress.finish("Done")
    text = out.getvalue()
    bar, summary = text.rsplit("\n", 2)[:2]
    assert "\n" not in bar and bar.count("\r") >= 2  # one line, rewritten in place
    assert "100%" in bar and "2/2" in bar and "frame 3" in bar
    assert summary == "Done" and text.endswith("\nDone\n")
    assert err.getvalue() == "WARNING: a warning while the bar is drawn\n"


def test_reports_from_two_threads_keep_whole_lines(tmp_path: Path) -> None:
    """The writer thread reports frames while the main thread warns, on one stream: each
    line arrives whole and every count is kept (without the lock the two threads' text and
    newlines interleave through the unbuffered wrapper, as under ``python -u``)."""
    path = tmp_path / "log"
    with path.open("wb", buffering=0) as raw:
        stream = io.TextIOWrapper(raw, write_through=True)  # type: ignore[arg-type]
        progress = Progress("json", total=4000, out=stream, err=stream)

        def report(writer: bool) -> None:
            for i in range(2000):
                if writer:
                    progress.frame_done(i, 0.1)
                else:
                    progress.warning(f"w{i}")

        threads = [threading.Thread(target=report, args=(w,)) for w in (False, True)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        stream.flush()
        stream.detach()
    lines = path.read_text().splitlines()
    warnings = [line for line in lines if line.startswith("WARNING: ")]
    events = [json.loads(line) for line in lines if not line.startswith("WARNING: ")]
    assert warnings == [f"WARNING: w{i}" for i in range(2000)]
    assert [e["index"] for e in events] == list(range(1, 2001))
    assert progress.done == 2000
