"""Run an evaluation: read the sequences, produce the baselines, score every method per frame.

Frames are streamed: per frame the reference, the denoised file, the input frame and every
baseline's image are held once, plus each method's previous display image (for the temporal
error) and the display images of the contact-sheet frames. Every file is checked before
any work starts, so a missing reference fails in a second, not after the baselines ran.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from svgf_cli import __version__
from svgf_cli.errors import InputError, UsageError
from svgf_cli.evaluate import metrics
from svgf_cli.evaluate.baselines import BASELINES, TEMPORAL_BASELINES, Method, make_method
from svgf_cli.evaluate.report import EvaluationReport, FrameScore, MethodResult
from svgf_cli.filters.params import DEFAULT_PRESET, PRESETS, SVGFParams
from svgf_cli.frame import Frame
from svgf_cli.io.patterns import SequencePattern

if TYPE_CHECKING:
    from svgf_cli.io.layers import LayerMapping

SVGF = "svgf"
INPUT = "input"
REFERENCE = "reference"  # the key of the reference's kept display frames

Log = Callable[[str], None]


@dataclass
class EvaluationRequest:
    """What to compare: file patterns, frames, baselines and their parameters."""

    output: str
    reference: str
    input: str | None = None
    frames: Sequence[int] | None = None
    baselines: Sequence[str] = ()
    params: SVGFParams = field(default_factory=lambda: PRESETS[DEFAULT_PRESET])
    preset: str = DEFAULT_PRESET
    layers: str = "svgf"
    signals: str = "auto"
    contact_frames: Sequence[int] = ()
    # More denoised sequences scored from files like ``output``: (method name, pattern).
    compare: Sequence[tuple[str, str]] = ()
    # ColorVideoVDP (svgf_cli.evaluate.perceptual): video and still JOD of these methods
    # (None: every method; empty: none), and the svgf output's heat map frames (jod_map).
    jod: Sequence[str] | None = ()
    jod_map: bool = False
    # Methods whose display frames the report keeps (``report.displays``; "reference" for
    # the reference's), e.g. for an animation.
    keep_displays: Sequence[str] = ()


@dataclass
class ContactFrame:
    """Display images of one frame for the contact sheet, keyed by method name."""

    frame: int
    reference: np.ndarray
    images: dict[str, np.ndarray]
    error_map: np.ndarray | None  # FLIP map of the svgf output; None when it is flagged


@dataclass
class _Track:
    """One method's running state: its results and its previous display image."""

    result: MethodResult
    method: Method | None = None  # None: read from files (``pattern``)
    pattern: SequencePattern | None = None
    previous: np.ndarray | None = None
    previous_frame: int | None = None


def resolve_frames(output: SequencePattern, text: str, spec: Sequence[int] | None) -> list[int]:
    """The frames to evaluate: ``spec`` when given, else every output frame on disk."""
    if spec is not None:
        frames = sorted(set(spec))
        if not frames:
            raise UsageError("--frames selects no frame")
        return frames
    frames = output.frames_on_disk()
    if not frames:
        where = output.directory if str(output.directory) else Path(".")
        reason = "no denoised files match the pattern"
        if not where.is_dir():
            reason += f" (directory {where} does not exist)"
        raise InputError(reason, text)
    return frames


def _require(path: Path, what: str, frame: int) -> None:
    if not path.is_file():
        raise InputError(f"{what} for frame {frame} not found", str(path))


def _check_shape(image: np.ndarray, reference: np.ndarray, path: Path, ref_path: Path) -> None:
    if image.shape[1:] != reference.shape[1:]:
        h, w = image.shape[1:]
        rh, rw = reference.shape[1:]
        raise InputError(
            f"resolution {w}x{h} does not match the reference {ref_path} ({rw}x{rh})", str(path)
        )


def _settings(
    request: EvaluationRequest, oidn_version: str | None, signals: str | None = None
) -> dict[str, object]:
    from svgf_cli.evaluate.baselines import oidn_prefilters

    settings: dict[str, object] = {
        "svgf_version": __version__,
        "tone_map": metrics.TONE_MAP_DESCRIPTION,
        "relmse_epsilon": metrics.RELMSE_EPSILON,
        "ssim": {
            "window": metrics.SSIM_WINDOW,
            "sigma": metrics.SSIM_SIGMA,
            "k1": metrics.SSIM_K1,
            "k2": metrics.SSIM_K2,
            "on": "tone-mapped R, G, B separately, then averaged; valid pixels only",
        },
        "flip": {"mode": metrics.FLIP_MODE, "on": "tone-mapped sRGB images", "ppd": 67},
        "temporal": "consecutive frame numbers only; undefined on a method's first frame",
        "baselines": list(request.baselines),
    }
    if signals is not None:  # the set the --input frames were read as
        settings["signals"] = signals
    if any(b in ("accumulate", "atrous", "forward", "bidirectional") for b in request.baselines):
        settings["preset"] = request.preset
        settings["params"] = json.loads(request.params.to_json())
    if oidn_version is not None:
        settings["oidn"] = {
            "package": f"pyoidn {oidn_version}",
            "filter": "RT",
            "hdr": True,
            "clean_aux": True,
            "quality": "high",
        }
        if oidn_prefilters(request.layers):
            settings["oidn"]["prefilter"] = (  # type: ignore[index]
                "oidn: albedo and normal denoised first by their own RT filters (noisy "
                "1-spp aux); oidn-noprefilter: aux as given")
    return settings


def _check_compare(request: EvaluationRequest, baselines: Sequence[str]) -> None:
    """Compared sequences need names of their own (not svgf, input or a baseline's)."""
    taken = {SVGF, INPUT, *baselines}
    for name, _pattern in request.compare:
        if not name or any(c.isspace() for c in name):
            raise UsageError(f"compared method name {name!r} must be a word without spaces")
        if name in taken:
            raise UsageError(f"compared method name {name!r} is used twice or is reserved")
        taken.add(name)


def _source(name: str, request: EvaluationRequest) -> str:
    if name == SVGF:
        return SequencePattern.parse(request.output).display
    if name == INPUT:
        assert request.input is not None
        return SequencePattern.parse(request.input).display
    from svgf_cli.evaluate.baselines import oidn_prefilters

    aux = "prefiltered albedo + normal" if oidn_prefilters(request.layers) else (
        "clean albedo + normal")
    return {
        "oidn": f"baseline: Intel OIDN per frame (RT, HDR, {aux})",
        "oidn-noprefilter": "baseline: Intel OIDN per frame (RT, HDR, albedo + normal as "
        "given, taken as clean)",
        "accumulate": "baseline: SVGF temporal accumulation only (atrous_iterations=0)",
        "atrous": "baseline: SVGF a-trous without temporal reuse (temporal=False)",
        "forward": "baseline: SVGF, causal (bidirectional=False)",
        "bidirectional": "baseline: SVGF, bidirectional (bidirectional=True)",
    }[name]


@dataclass
class _Sequences:
    """The parsed file patterns of an evaluation and its frames, every file checked."""

    output: SequencePattern
    reference: SequencePattern
    input: SequencePattern | None
    compare: list[tuple[str, SequencePattern]]
    frames: list[int]  # scored
    fed: list[int]  # read: the scored frames and, for temporal baselines, those in between


def _checked_baselines(request: EvaluationRequest) -> list[str]:
    """The requested baselines, once each; UsageError for an unknown one or no input."""
    unknown = [b for b in request.baselines if b not in BASELINES]
    if unknown:
        raise UsageError(f"unknown baseline {unknown[0]!r} (choose from {', '.join(BASELINES)})")
    baselines = list(dict.fromkeys(request.baselines))
    if baselines and request.input is None:
        raise UsageError("--baseline needs --input: the baselines run on the noisy input frames")
    return baselines


def _sequences(request: EvaluationRequest, baselines: Sequence[str]) -> _Sequences:
    """Parse the patterns, pick the frames and check every file exists before any work."""
    _check_compare(request, baselines)
    out_pattern = SequencePattern.parse(request.output)
    compare_patterns = [(n, SequencePattern.parse(p)) for n, p in request.compare]
    ref_pattern = SequencePattern.parse(request.reference)
    in_pattern = SequencePattern.parse(request.input) if request.input else None
    frames = resolve_frames(out_pattern, request.output, request.frames)
    # Temporal baselines must see every frame in between, not only the scored ones.
    temporal = any(b in TEMPORAL_BASELINES for b in baselines)
    fed = list(range(frames[0], frames[-1] + 1)) if temporal else frames
    for frame in frames:
        _require(out_pattern.path(frame), "denoised output", frame)
        for name, pattern in compare_patterns:
            _require(pattern.path(frame), f"{name} output", frame)
        _require(ref_pattern.path(frame), "reference", frame)
    if in_pattern is not None:
        for frame in fed:
            _require(in_pattern.path(frame), "input", frame)
    missing_contact = sorted(set(request.contact_frames) - set(frames))
    if missing_contact:
        raise UsageError(f"--contact-frames {missing_contact[0]} is not an evaluated frame")
    return _Sequences(out_pattern, ref_pattern, in_pattern, compare_patterns, frames, fed)


def _tracks(
    request: EvaluationRequest, seqs: _Sequences, baselines: Sequence[str]
) -> tuple[list[_Track], str | None]:
    """One track per method (svgf, compared sequences, baselines, input) and the pyoidn
    version when the oidn baseline runs."""
    tracks: list[_Track] = [_Track(MethodResult(SVGF, _source(SVGF, request)), None, seqs.output)]
    for name, pattern in seqs.compare:
        tracks.append(_Track(MethodResult(name, pattern.display), None, pattern))
    oidn_version = None
    in_pattern = seqs.input
    for name in baselines:
        assert in_pattern is not None
        method = make_method(name, request.params, [(f, in_pattern.path(f)) for f in seqs.fed],
                             request.layers)
        tracks.append(_Track(MethodResult(name, _source(name, request)), method))
        if name in ("oidn", "oidn-noprefilter"):
            from importlib.metadata import version

            oidn_version = version("pyoidn")
    if in_pattern is not None:
        input_method = make_method(INPUT, request.params)
        tracks.append(_Track(MethodResult(INPUT, _source(INPUT, request)), input_method))
    return tracks, oidn_version


def _input_mapping(request: EvaluationRequest, seqs: _Sequences, say: Log) -> LayerMapping:
    """The layer mapping files are read with; with an input sequence, fixed to the signal set
    decided on its first frame (one set for the whole sequence)."""
    from svgf_cli.io.exr import fix_signal_set
    from svgf_cli.io.layers import build_mapping

    mapping = build_mapping(request.layers, signals=request.signals)
    if seqs.input is not None:
        mapping, decided = fix_signal_set(seqs.input.path(seqs.fed[0]), mapping)
        if decided.signal_warning:
            say(f"WARNING: {decided.signal_warning}")
        del decided
    return mapping


@dataclass
class _Scorer:
    """Scores every track frame by frame; keeps the reference's previous display image (for
    the temporal error) and the contact-sheet frames."""

    seqs: _Sequences
    tracks: list[_Track]
    mapping: LayerMapping
    contact_wanted: set[int]
    contacts: list[ContactFrame] = field(default_factory=list)
    ref_previous: np.ndarray | None = None
    ref_previous_frame: int | None = None
    # Display images kept for the video metrics: the reference's and, per method, its own.
    keep: set[str] = field(default_factory=set)
    kept: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def advance(self, input_frame: Frame | None) -> None:
        """A frame that is not scored: only advance the stateful baselines through the gap."""
        for track in self.tracks:
            if track.method is not None and track.result.name != INPUT:
                assert input_frame is not None
                track.method.process(input_frame)

    def score(self, frame: int, input_frame: Frame | None) -> None:
        """Score every track's image of ``frame`` against the reference."""
        from svgf_cli.io.exr import read_rgb

        in_pattern = self.seqs.input
        ref_path = self.seqs.reference.path(frame)
        reference, _ = read_rgb(ref_path, self.mapping)
        bad = metrics.nonfinite_pixels(reference)
        if bad:
            raise InputError(f"reference has {bad} NaN or infinite pixel(s)", str(ref_path))
        if input_frame is not None and in_pattern is not None:
            _check_shape(input_frame.albedo, reference, in_pattern.path(frame), ref_path)
        ref_display = metrics.tone_map(reference)
        wanted = frame in self.contact_wanted
        contact = ContactFrame(frame, ref_display, {}, None) if wanted else None
        for track in self.tracks:
            image, file = self._image(track, frame, input_frame, reference, ref_path)
            consecutive = (
                track.previous_frame is not None
                and track.previous_frame == frame - 1
                and self.ref_previous_frame == frame - 1
            )
            score, display, flip_map = score_frame(
                frame,
                image,
                reference,
                ref_display,
                previous=track.previous if consecutive else None,
                ref_previous=self.ref_previous if consecutive else None,
            )
            score.file = file
            track.result.frames.append(score)
            if track.result.name in self.keep and display is not None:
                self.kept.setdefault(track.result.name, []).append(display)
            track.previous = display
            track.previous_frame = frame if display is not None else None
            if contact is not None:
                contact.images[track.result.name] = (
                    display if display is not None else np.zeros_like(ref_display)
                )
                if track.result.name == SVGF:
                    contact.error_map = flip_map
        self.ref_previous, self.ref_previous_frame = ref_display, frame
        if self.keep:
            self.kept.setdefault(REFERENCE, []).append(ref_display)
        if contact is not None:
            self.contacts.append(contact)

    def _image(
        self,
        track: _Track,
        frame: int,
        input_frame: Frame | None,
        reference: np.ndarray,
        ref_path: Path,
    ) -> tuple[np.ndarray, str | None]:
        """A track's image of ``frame`` (read from its file or made by its method) and the
        file it comes from."""
        if track.pattern is not None:
            from svgf_cli.io.exr import read_rgb

            path = track.pattern.path(frame)
            image, _ = read_rgb(path, self.mapping)
            _check_shape(image, reference, path, ref_path)
            return image, str(path)
        assert input_frame is not None
        image = track.method.process(input_frame)
        in_pattern = self.seqs.input
        is_input = track.result.name == INPUT and in_pattern is not None
        return image, str(in_pattern.path(frame)) if is_input else None


def run_evaluation(
    request: EvaluationRequest, log: Log | None = None
) -> tuple[EvaluationReport, list[ContactFrame]]:
    """Score the denoised sequence, the raw input and the baselines against the reference."""
    say = log or (lambda _msg: None)
    baselines = _checked_baselines(request)
    seqs = _sequences(request, baselines)
    tracks, oidn_version = _tracks(request, seqs, baselines)

    from svgf_cli.io.exr import read_frame

    mapping = _input_mapping(request, seqs, say)
    scorer = _Scorer(seqs, tracks, mapping, set(request.contact_frames))
    jod_names = _jod_names(request, tracks)
    metric = None
    if jod_names:
        from svgf_cli.evaluate.perceptual import load_metric

        metric = load_metric()  # fails before the work when cvvdp/torch are missing
    scorer.keep = set(jod_names) | set(request.keep_displays)
    scored = set(seqs.frames)
    for index, frame in enumerate(seqs.fed):
        input_frame: Frame | None = None
        if seqs.input is not None:
            input_frame = read_frame(seqs.input.path(frame), mapping).frame
        if frame not in scored:
            scorer.advance(input_frame)
            continue
        say(f"frame {frame} ({index + 1}/{len(seqs.fed)})")
        scorer.score(frame, input_frame)

    report = EvaluationReport(
        frames=seqs.frames,
        methods=[t.result for t in tracks],
        inputs={
            "output": request.output,
            "reference": request.reference,
            "input": request.input,
        },
        settings=_settings(request, oidn_version, mapping.signals if seqs.input else None),
    )
    if metric is not None:
        _score_jod(report, scorer, jod_names, metric, request.jod_map, say)
    report.displays = {n: f for n, f in scorer.kept.items()
                       if n in request.keep_displays or n == REFERENCE}  # fmt: skip
    return report, scorer.contacts


def _jod_names(request: EvaluationRequest, tracks: Sequence[_Track]) -> list[str]:
    """The methods whose JOD is measured, in report order."""
    names = [t.result.name for t in tracks]
    if request.jod is None:
        return names
    unknown = [n for n in request.jod if n not in names]
    if unknown:
        raise UsageError(f"--jod-methods: no method {unknown[0]!r} (have {', '.join(names)})")
    return [n for n in names if n in request.jod]


def _score_jod(report: EvaluationReport, scorer: _Scorer, names: Sequence[str], metric: object,
               heat: bool, say: Log) -> None:
    """Video and still JOD of every named, unflagged method (and svgf's heat map)."""
    from svgf_cli.evaluate.perceptual import JOD_DESCRIPTION, jod_scores, load_metric

    reference = scorer.kept.get(REFERENCE, [])
    report.settings["jod"] = JOD_DESCRIPTION
    for name in names:
        frames = scorer.kept.get(name, [])
        if report.method(name).flagged or len(frames) != len(reference):
            continue
        say(f"ColorVideoVDP: {name}")
        score = jod_scores(frames, reference, metric)  # type: ignore[arg-type]
        report.jod[name] = score
    if heat and SVGF in report.jod:
        map_metric = load_metric(heatmap=True)
        report.jod[SVGF].heatmap = jod_scores(scorer.kept[SVGF], reference, map_metric,
                                              stills=False).heatmap  # fmt: skip


def score_frame(
    frame: int,
    image: np.ndarray,
    reference: np.ndarray,
    ref_display: np.ndarray,
    previous: np.ndarray | None = None,
    ref_previous: np.ndarray | None = None,
) -> tuple[FrameScore, np.ndarray | None, np.ndarray | None]:
    """Every metric of one image against its reference.

    Returns the score, the image's display version (None when flagged) and its FLIP error
    map. An image with NaN/Inf pixels is flagged: no metric is computed for it.
    """
    bad = metrics.nonfinite_pixels(image)
    if bad:
        return FrameScore(frame, {k: None for k in metrics.METRIC_KEYS}, bad), None, None
    display = metrics.tone_map(image)
    flip_mean, flip_map = metrics.flip(display, ref_display)
    temporal = None
    if previous is not None and ref_previous is not None:
        temporal = metrics.temporal_error(display, previous, ref_display, ref_previous)
    hot_max, hot_share = metrics.hot_pixels(image, reference)
    values = {
        "rmse": metrics.rmse(image, reference),
        "relmse": metrics.relmse(image, reference),
        "relmse_trimmed": metrics.relmse_trimmed(image, reference),
        "psnr": metrics.psnr(display, ref_display),
        "ssim": metrics.ssim(display, ref_display),
        "flip": flip_mean,
        "temporal": temporal,
        "hot_max": hot_max,
        "hot_share": hot_share,
    }
    return FrameScore(frame, values), display, flip_map
