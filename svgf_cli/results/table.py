"""What `make results` runs: the bundled sequences and the methods, as data.

Adding a sequence is one :class:`SequenceSpec` in :data:`SEQUENCES`; adding a method is one
line in :data:`METHODS`: a name plus the extra ``svgf denoise`` options, e.g.
``denoised("svgf-bidirectional", "--bidirectional", "...")``. A method whose options the
installed ``svgf denoise`` does not know is skipped with a note on the page, so the table
can name options that other branches are still adding.

Sequence tags (what the checks in :mod:`svgf_cli.results.checks` select on):

* ``static-lighting``: lighting is static relative to the surfaces (issue 10's control);
* ``lag``: lighting changes relative to the surfaces (moving or switched lights, moving
  shadows, moving reflections): where history lags;
* ``camera-motion``, ``moving-objects``: what moves (issue 13's sequences);
* ``cycles``: rendered by Blender Cycles; ``lobes``: the inputs carry per-lobe light passes.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

SVGF = "svgf"  # the product: `svgf denoise` with the default preset (paper + anti-lag)
PAPER = "svgf-paper"
SPATIAL = "svgf-no-temporal"
LOBES = "svgf-lobes"
COMBINED = "svgf-combined"
BIDIRECTIONAL = "svgf-bidirectional"
INPUT = "input"
OIDN = "oidn"
OIDN_NOPREFILTER = "oidn-noprefilter"
# Scored with ColorVideoVDP when the `perceptual` extra is installed (about 20 s each per
# 16-frame sequence on 2 cores; issue 29).
JOD_METHODS: tuple[str, ...] = (SVGF, BIDIRECTIONAL, OIDN, OIDN_NOPREFILTER)
# Columns of each sequence's animation, left to right: (method or "reference", label).
ANIMATION: tuple[tuple[str, str], ...] = (
    (INPUT, "input"),  # the noisy frames as rendered (1 spp, or 4 for cycles/roll4)
    (SVGF, "svgf"),
    (OIDN, "OIDN"),
    ("reference", "reference"),
)


@dataclass(frozen=True)
class Event:
    """Something that happens at a frame; ``lighting_step``: the light changed abruptly there
    (the frame is the first one with the new lighting), so issue 10's recovery target
    applies."""

    frame: int
    text: str
    lighting_step: bool = True


@dataclass(frozen=True)
class SequenceSpec:
    """One bundled sequence: where its files are, how to read them, what it tests."""

    folder: str  # relative to the repository root
    about: str  # what the sequence shows and tests (one sentence, for the page)
    tags: frozenset[str]
    aovs: str = "svgf"  # --preset-aovs for reading the inputs
    events: tuple[Event, ...] = ()
    contact_frames: tuple[int, ...] = ()  # rows of the contact sheet (telling frames)
    inputs: str = "in.####.exr"
    references: str = "ref.####.exr"

    @property
    def name(self) -> str:
        """File-name-safe identifier: the folder under ``testdata/``, ``/`` -> ``-``."""
        return self.folder.removeprefix("testdata/").replace("/", "-")

    def has(self, tag: str) -> bool:
        return tag in self.tags


@dataclass(frozen=True)
class MethodSpec:
    """One method on the page: made by ``svgf denoise`` with ``options`` (``baseline`` is
    None), or an in-memory baseline of ``svgf evaluate`` (``options`` is empty)."""

    name: str
    about: str
    options: tuple[str, ...] = ()
    baseline: str | None = None
    needs: str | None = None  # a sequence tag the method needs (e.g. "lobes")
    contact: bool = False  # a column of the contact sheets
    unless: str | None = None  # a sequence tag the method cannot run on (e.g. "colour-only")

    def applies_to(self, sequence: SequenceSpec) -> bool:
        return ((self.needs is None or sequence.has(self.needs))
                and (self.unless is None or not sequence.has(self.unless)))

    @property
    def command(self) -> str:
        if self.baseline is not None:
            return f"svgf evaluate --baseline {self.baseline}"
        return "svgf denoise " + shlex.join(self.options) if self.options else "svgf denoise"


def denoised(
    name: str, options: str, about: str, *, needs: str | None = None, contact: bool = True,
    unless: str | None = None,
) -> MethodSpec:
    """A method made by ``svgf denoise OPTIONS`` (added to the sequence's own options)."""
    return MethodSpec(name, about, tuple(shlex.split(options)), needs=needs, contact=contact,
                      unless=unless)


def baseline(
    name: str, about: str, *, contact: bool = False, needs: str | None = None
) -> MethodSpec:
    """A baseline ``svgf evaluate`` produces in memory (``--baseline NAME``)."""
    return MethodSpec(name, about, baseline=name, contact=contact, needs=needs)


# The first entry is the product (scored as `svgf`); every other method is compared with it.
METHODS: tuple[MethodSpec, ...] = (
    denoised(SVGF, "--preset default", "the default preset: the paper's filter with anti-lag"),
    denoised(PAPER, "--preset paper", "the paper's parameters, as published (no anti-lag)"),
    denoised(SPATIAL, "--preset default --set temporal=off", "spatial only: every frame cold"),
    denoised(LOBES, "--signals lobes", "one signal per lobe (diffuse, glossy, ...)", needs="lobes"),
    denoised(
        "svgf-lobes-split",
        "--signals lobes-split",
        "per lobe, direct and indirect apart",
        needs="lobes",
        contact=False,
    ),
    denoised(
        "svgf-direct-indirect",
        "--signals direct-indirect",
        "two signals, direct and indirect light",
        contact=False,
        unless="colour-only",
    ),
    denoised(COMBINED, "--signals combined", "one signal: the combined colour", contact=False),
    denoised(BIDIRECTIONAL, "--bidirectional", "forward and time-reversed passes combined"),
    baseline(
        "oidn",
        "Intel OIDN per frame (RT, HDR, quality high; albedo + normal as clean guides on svgf "
        "trace inputs, prefiltered by OIDN first on Cycles' noisy 1-spp ones)",
        contact=True,
    ),
    baseline(
        "oidn-noprefilter",
        "Intel OIDN per frame with Cycles' noisy albedo + normal taken as clean (no prefilter)",
        needs="cycles",
    ),
    baseline("accumulate", "temporal accumulation only (default preset, no a-trous)"),
    baseline("atrous", "a-trous without temporal reuse (default preset), in memory"),
)

_STATIC = frozenset({"static-lighting"})

SEQUENCES: tuple[SequenceSpec, ...] = (
    SequenceSpec(
        "testdata/seq",
        "svgf trace Cornell box with a checker floor: slow camera move, a block sliding and "
        "turning; static lighting (10 frames, 128x72, 1 spp; 1024-spp references).",
        _STATIC | {"camera-motion", "moving-objects"},
    ),
    SequenceSpec(
        "testdata/seq_box",
        "testdata/seq's inputs against references box-filtered over 4x4 positions in each "
        "pixel (svgf trace --reference-supersample 4), as a production renderer's converged "
        "frame: texture and object edges anti-aliased where the 1-spp input is not.",
        _STATIC | {"camera-motion", "moving-objects"},
        inputs="../seq/in.####.exr",
    ),
    SequenceSpec(
        "testdata/seq_jit",
        "testdata/seq traced with jittered samples (svgf trace --jitter: each pixel's one "
        "sample, G-buffer included, at a random position in the pixel, a new one every "
        "frame, as Mitsuba's 1-spp frames), against seq_box's box-filtered references.",
        _STATIC | {"camera-motion", "moving-objects"},
        references="../seq_box/ref.####.exr",
    ),
    SequenceSpec(
        "testdata/lag/light_slide_dim",
        "The ceiling light slides 16 mm a frame right to left (static camera) and dims to 45% "
        "at frame 10 (16 frames; 2048-spp references).",
        frozenset({"lag"}),
        events=(Event(10, "light dims to 45%"),),
        contact_frames=(10,),
    ),
    SequenceSpec(
        "testdata/lag/light_step",
        "Static scene and camera; the light drops to 30% on frames 6-10 and is back to 100% "
        "from frame 11.",
        frozenset({"lag"}),
        events=(Event(6, "light to 30%"), Event(11, "light back to 100%")),
        contact_frames=(6,),
    ),
    SequenceSpec(
        "testdata/lag/shadow",
        "Static camera and light; a sphere rolls 120 mm right and back (about 2 px a frame), "
        "its shadow moving over the static floor; frames 8 and 9 show the same pose.",
        frozenset({"lag", "moving-objects"}),
        contact_frames=(5,),
    ),
    SequenceSpec(
        "testdata/lag/camera",
        "The control: static lighting and objects, the camera moves right, up and closer.",
        _STATIC | {"camera-motion"},
    ),
    SequenceSpec(
        "testdata/lag_jit/camera",
        "lag/camera traced with jittered samples (svgf trace --jitter, as Mitsuba's 1-spp "
        "frames) against references box-filtered over 4x4 positions (64 samples each): a pan "
        "of the kind a renderer that jitters its samples writes.",
        _STATIC | {"camera-motion"},
    ),
    SequenceSpec(
        "testdata/mitsuba/seq",
        "Mitsuba 3.9: testdata/seq's animation rendered by Mitsuba itself (path integrator "
        "with its defaults, independent sampler, box pixel filter, 1 spp; colour, albedo, "
        "normal and depth from one jittered sample, emission from a second render of the "
        "same samples; svgf trace's motion; 4096-spp references).",
        _STATIC | {"camera-motion", "moving-objects", "colour-only"},
    ),
    SequenceSpec(
        "testdata/mitsuba/lag/shadow",
        "Mitsuba 3.9: lag/shadow's animation (a sphere rolling over the floor, its shadow "
        "moving; static camera and light) rendered as testdata/mitsuba/seq (16 frames).",
        frozenset({"lag", "moving-objects", "colour-only"}),
        contact_frames=(5,),
    ),
    SequenceSpec(
        "testdata/mitsuba/lag/light_slide_dim",
        "Mitsuba 3.9: lag/light_slide_dim's animation (the ceiling light slides right to left "
        "and dims to 45% at frame 10; static camera) rendered as testdata/mitsuba/seq.",
        frozenset({"lag", "colour-only"}),
        events=(Event(10, "light dims to 45%"),),
        contact_frames=(10,),
    ),
    SequenceSpec(
        "testdata/mitsuba/lag/light_step",
        "Mitsuba 3.9: lag/light_step's animation (the light drops to 30% on frames 6-10, "
        "back to 100% from frame 11; static camera and scene) rendered as "
        "testdata/mitsuba/seq.",
        frozenset({"lag", "colour-only"}),
        events=(Event(6, "light to 30%"), Event(11, "light back to 100%")),
        contact_frames=(6,),
    ),
    SequenceSpec(
        "testdata/lag/glossy",
        "Glossy floor (roughness 0.25), gold sphere and steel block (metal); the light slides "
        "and the camera moves; lobe passes written.",
        frozenset({"lag", "camera-motion", "lobes"}),
        contact_frames=(8,),
    ),
    SequenceSpec(
        "testdata/cycles/roll",
        "Blender Cycles: camera dolly over a checker floor, a ball rolling across it (up to "
        "9 px a frame) with a soft shadow, glossy ball, gold bust, emissive panel, sky.",
        frozenset({"lag", "camera-motion", "moving-objects", "cycles", "lobes"}),
        aovs="cycles",
        contact_frames=(6,),
    ),
    SequenceSpec(
        "testdata/cycles/roll4",
        "Blender Cycles: cycles/roll's shot at 4 samples per pixel (the G-buffer a 4-sample "
        "average, blended at edges), against cycles/roll's references.",
        frozenset({"lag", "camera-motion", "moving-objects", "cycles", "lobes"}),
        aovs="cycles",
        contact_frames=(6,),
        references="../roll/ref.####.exr",
    ),
    SequenceSpec(
        "testdata/cycles/metal",
        "Blender Cycles: polished metal ball on a glossy checker floor reflecting a sweeping "
        "area light; a point light switches on at frame 6 (+50% mean brightness); slow camera.",
        frozenset({"lag", "camera-motion", "cycles", "lobes"}),
        aovs="cycles",
        events=(Event(6, "point light on"),),
        contact_frames=(6,),
    ),
    SequenceSpec(
        "testdata/cycles/production",
        "Blender Cycles: glass sphere, a fog box, thin metal wires, a box on a checker floor; "
        "three light groups (key, fill, env), the fill light on from frame 5; moving camera "
        "(8 frames).",
        frozenset({"lag", "camera-motion", "cycles", "lobes", "volume"}),
        aovs="cycles",
        events=(Event(5, "fill light on"),),
        contact_frames=(5,),
    ),
    SequenceSpec(
        "testdata/cycles/dof",
        "Blender Cycles: cycles/roll's shot with depth of field (f/0.03 at 35 mm, focused on "
        "the ball: 4-20 px circles of confusion at 128x72; 8 frames).",
        frozenset({"camera-motion", "moving-objects", "cycles", "lobes", "depth-of-field"}),
        aovs="cycles",
        contact_frames=(6,),
    ),
    SequenceSpec(
        "testdata/cycles/smoke",
        "Blender Cycles: a patchy smoke cloud, partly over the floor and a sphere, partly "
        "against the sky; sun, area light and sky; slow camera (8 frames).",
        frozenset({"camera-motion", "cycles", "lobes", "volume"}),
        aovs="cycles",
        contact_frames=(6,),
    ),
)
