"""The declarative table of `make results` names real sequences and well-formed methods."""

from __future__ import annotations

from pathlib import Path

import pytest

from svgf_cli.io.layers import AOV_PRESETS
from svgf_cli.results.run import frames_on_disk, unknown_options
from svgf_cli.results.table import METHODS, SEQUENCES, SVGF, SequenceSpec

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("spec", SEQUENCES, ids=lambda s: s.name)
def test_every_sequence_exists_with_a_reference_per_input_frame(spec: SequenceSpec) -> None:
    inputs, references = frames_on_disk(spec, REPO)
    assert len(inputs) >= 2, f"{spec.folder}: no input sequence {spec.inputs}"
    assert inputs == references, f"{spec.folder}: input and reference frames differ"
    assert inputs == list(range(inputs[0], inputs[-1] + 1)), "frames must be consecutive"
    assert spec.aovs in AOV_PRESETS
    for frame in [*spec.contact_frames, *(e.frame for e in spec.events)]:
        assert frame in inputs, f"{spec.folder}: frame {frame} is not in the sequence"
    assert spec.tags and spec.about


def test_sequence_names_are_unique_and_file_safe() -> None:
    names = [s.name for s in SEQUENCES]
    assert len(set(names)) == len(names)
    assert all(n and "/" not in n and " " not in n for n in names)
    assert SequenceSpec("testdata/lag/shadow", "x", frozenset()).name == "lag-shadow"


def test_static_and_lag_sequences_are_declared() -> None:
    static = {s.name for s in SEQUENCES if s.has("static-lighting")}
    assert {"seq", "lag-camera"} <= static, "issue 10's static-lighting controls"
    lag = {s.name for s in SEQUENCES if s.has("lag")}
    assert not static & lag
    assert any(e.lighting_step for s in SEQUENCES for e in s.events)


def test_methods_are_one_line_each_and_the_product_comes_first() -> None:
    names = [m.name for m in METHODS]
    assert names[0] == SVGF and METHODS[0].baseline is None
    assert len(set(names)) == len(names)
    for method in METHODS:
        assert (method.baseline is None) == bool(method.options), method.name
        assert method.name not in ("input",)
    assert METHODS[0].command == "svgf denoise --preset default"


def test_unknown_options_are_found_in_the_help_text() -> None:
    help_text = "  --preset [default|paper]\n  --temporal / --no-temporal  Reuse history.\n"
    assert unknown_options(["--preset", "paper", "--no-temporal"], help_text) == []
    assert unknown_options(["--signals", "lobes", "--bidirectional"], help_text) == [
        "--signals",
        "--bidirectional",
    ]
    # A prefix of a known option is not that option.
    assert unknown_options(["--pre"], help_text) == ["--pre"]
    assert unknown_options(["--temporal=1"], help_text) == []


def test_a_method_skips_the_sequences_it_cannot_run_on() -> None:
    """The direct/indirect signal set needs light passes: a colour-only sequence (Mitsuba's
    one-sample frames) is not given it; every other method still applies there."""
    mitsuba = next(s for s in SEQUENCES if s.name == "mitsuba-seq")
    assert mitsuba.has("colour-only")
    skipped = [m.name for m in METHODS if not m.applies_to(mitsuba) and m.needs is None]
    assert skipped == ["svgf-direct-indirect"]
    seq = next(s for s in SEQUENCES if s.name == "seq")
    assert next(m for m in METHODS if m.name == "svgf-direct-indirect").applies_to(seq)
