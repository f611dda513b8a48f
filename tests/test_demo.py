"""`make demo`'s picture: the last frame as input | svgf | reference, labelled."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
from test_cli_support import REPO

from svgf_cli.demo import write_picture

SEQ = REPO / "testdata" / "seq"


def test_picture_has_three_labelled_columns(tmp_path: Path) -> None:
    picture = tmp_path / "demo.png"
    # The bundled noisy frames stand in for the denoised ones: only the layout is tested.
    noisy = str(SEQ / "in.####.exr")
    write_picture(noisy, noisy, str(SEQ / "ref.####.exr"), picture)
    image = matplotlib.image.imread(picture)
    height, width = image.shape[:2]
    assert 2.5 < width / height < 6  # one row of three 16:9 cells (four would be wider)
    # Three image cells: long runs of non-white pixels along a row through their middle
    # (the background is white; the row label's letters make only short runs).
    row = image[int(height * 0.5), :, :3].mean(axis=1) < 0.95
    runs, length = [], 0
    for inside in [*row, False]:
        if inside:
            length += 1
        elif length:
            runs.append(length)
            length = 0
    assert len([r for r in runs if r > width / 10]) == 3


def test_animation_shows_every_frame_side_by_side(tmp_path: Path) -> None:
    import importlib.util

    from PIL import Image

    from svgf_cli.demo import write_animation
    from svgf_cli.evaluate.animation import GAP, LABEL_HEIGHT

    path = tmp_path / "demo.webp"
    noisy = str(SEQ / "in.####.exr")
    labels = write_animation(noisy, noisy, str(SEQ / "ref.####.exr"), path)
    oidn = importlib.util.find_spec("pyoidn") is not None
    assert labels == ["input (1 spp)", "svgf", *(["OIDN"] if oidn else []), "reference"]
    with Image.open(path) as image:
        assert image.n_frames == 10  # testdata/seq's frames 1-10
        columns = len(labels)
        assert image.size == (columns * 128 + (columns - 1) * GAP, 72 + LABEL_HEIGHT)
