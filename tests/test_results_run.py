"""`make results` end to end on two frames of the bundled sequence (in-process denoise)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest
from click.testing import CliRunner

from svgf_cli.cli import cli
from svgf_cli.results.__main__ import generate
from svgf_cli.results.run import DenoiseOutcome
from svgf_cli.results.table import METHODS, SEQUENCES, denoised

REPO = Path(__file__).resolve().parents[1]


class InProcessDenoise:
    """`svgf denoise` through click in this process (no interpreter start-up per run)."""

    def __init__(self) -> None:
        self.calls: list[list[str]] = []

    def help_text(self) -> str:
        return CliRunner().invoke(cli, ["denoise", "--help"]).output

    def denoise(self, args: Sequence[str]) -> DenoiseOutcome:
        self.calls.append(list(args))
        result = CliRunner().invoke(cli, ["denoise", *args])
        return DenoiseOutcome(result.exit_code, result.stderr)


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    docs = tmp_path_factory.mktemp("docs")
    (docs / "results").mkdir()
    (docs / "results" / "stale_errors.png").write_bytes(b"old")
    by_name = {m.name: m for m in METHODS}
    methods = [
        by_name["svgf"],
        by_name["svgf-paper"],
        by_name["atrous"],
        denoised("svgf-future", "--no-such-option 3", "an option another branch adds"),
    ]
    seq = next(s for s in SEQUENCES if s.name == "seq")
    spec = type(seq)(seq.folder, seq.about, seq.tags, contact_frames=(2,))
    runner = InProcessDenoise()
    runs, checks = generate(docs, [spec], methods, runner, frames=[1, 2], log=lambda _m: None)
    first = {p.name: p.read_bytes() for p in sorted((docs / "results").iterdir())}
    page = (docs / "results.md").read_text()
    generate(docs, [spec], methods, runner, frames=[1, 2], log=lambda _m: None)
    second = {p.name: p.read_bytes() for p in sorted((docs / "results").iterdir())}
    return {"docs": docs, "runs": runs, "checks": checks, "page": page, "first": first,
            "second": second, "runner": runner}


def test_every_method_is_scored_and_the_unknown_one_skipped(generated: dict) -> None:
    (run,) = generated["runs"]
    assert run.names == ["svgf", "svgf-paper", "atrous", "input"]
    assert run.report.frames == [1, 2]
    calls = generated["runner"].calls
    assert len(calls) == 4, "svgf and svgf-paper, twice; never the unknown option"
    assert all("--frames" in c and "1,2" in c for c in calls)
    page = generated["page"]
    assert "| `svgf-future` |" in page and "has no `--no-such-option` option yet" in page
    svgf_rel = run.report.method("svgf").summary("relmse_trimmed")
    assert 0.0 < svgf_rel < run.report.method("input").summary("relmse_trimmed")


def test_page_json_and_images_are_written_and_deterministic(generated: dict) -> None:
    first, second = generated["first"], generated["second"]
    assert set(first) == {"seq.json", "seq_curves.png", "seq_contact.png", "seq_anim.webp"}, (
        "stale file removed")
    assert first == second, "same inputs, same bytes (JSON and PNGs)"
    assert (generated["docs"] / "results.md").read_text() == generated["page"]
    report = json.loads(first["seq.json"])
    assert report["inputs"]["reference"] == "testdata/seq/ref.####.exr"
    assert "/tmp" not in first["seq.json"].decode(), "no temporary paths in the published JSON"
    sources = {m["name"]: m["source"] for m in report["methods"]}
    assert sources["svgf-paper"] == "svgf denoise --preset paper"
    for png in ("seq_curves.png", "seq_contact.png"):
        assert first[png][:8] == b"\x89PNG\r\n\x1a\n" and len(first[png]) < 150_000
    from PIL import Image

    with Image.open(generated["docs"] / "results" / "seq_anim.webp") as animation:
        assert animation.n_frames == 2  # the evaluated frames; input | svgf | reference
        assert animation.size[0] == 3 * 256 + 2 * 2


def test_page_has_tables_findings_and_checklist(generated: dict) -> None:
    page = generated["page"]
    assert "## `testdata/seq`" in page
    assert "![contact sheet](results/seq_contact.png)" in page
    assert "(results/seq_anim.webp)" in page and "ColorVideoVDP, JOD" in page
    assert "relMSE (trimmed) ↓" in page and "Hot max ↓" in page
    assert "What this shows:" in page and "`svgf` against the paper preset" in page
    assert "## Issue targets" in page
    statuses = {c.target: c.status for c in generated["checks"]}
    static = next(t for t in statuses if "static-lighting" in t)
    assert statuses[static] in ("PASS", "FAIL"), "seq is static: the check has numbers"
    bidir = [c for c in generated["checks"] if c.issue == 13]
    assert bidir and all(c.status == "SKIP" for c in bidir)
