"""Farm submissions of one `svgf denoise` job: OpenJD job parameters and Deadline 10 files.

Both describe the same chunks as ``plan_chunks``: the farm splits the frames into tasks of
``chunk_size`` frames and every task runs ``svgf denoise --frames A-B --warmup W``, which
replays its own warm-up from disk. Nothing here runs anything; ``svgf plan`` prints or writes
what these functions return.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from svgf_cli.filters.params import DEFAULT_PRESET
from svgf_cli.io.patterns import SequencePattern

# The OpenJD template shipped in the repository (farm/openjd/); its parameters are the keys
# of ``openjd_job_parameters``.
OPENJD_TEMPLATE = "farm/openjd/svgf-denoise.template.yaml"

# Options each farm task sets itself: a requeued task resumes instead of failing on the
# outputs its first attempt wrote.
RESUME_OPTIONS = ("--skip-existing",)


@dataclass(frozen=True)
class FarmJob:
    """What a farm job needs to know about the `svgf denoise` command it repeats."""

    input_pattern: str
    output: str
    frames: str
    chunk_size: int
    warmup: str  # "16" or "all"
    preset: str = DEFAULT_PRESET
    preset_aovs: str = "svgf"
    executable: str = "svgf"


def openjd_job_parameters(job: FarmJob) -> dict[str, object]:
    """The job parameters of the OpenJD template for ``job`` (``openjd run -p file://``)."""
    return {
        "InputPattern": job.input_pattern,
        "OutputPattern": job.output,
        "Frames": job.frames,
        "ChunkSize": job.chunk_size,
        "Warmup": job.warmup,
        "Preset": job.preset,
        "PresetAovs": job.preset_aovs,
        "SvgfExecutable": job.executable,
    }


def _deadline_word(word: str) -> str:
    """A word of a Deadline ``Arguments=`` line; whitespace-holding words in <QUOTE>s."""
    return f"<QUOTE>{word}<QUOTE>" if any(c.isspace() for c in word) or not word else word


def deadline_files(
    job: FarmJob, denoise_args: Sequence[str], name: str
) -> dict[str, Mapping[str, str]]:
    """Job info and plugin info (CommandLine plugin) of a Deadline 10 submission.

    Deadline cuts ``Frames`` into tasks of ``ChunkSize`` frames and substitutes each task's
    first and last frame into ``--frames <STARTFRAME>-<ENDFRAME>``.
    """
    words = ["denoise", *denoise_args, "--frames", "<STARTFRAME>-<ENDFRAME>"]
    words += ["--warmup", job.warmup]
    if not {"--overwrite", "--skip-existing"} & set(denoise_args):
        words += RESUME_OPTIONS
    job_info = {
        "Plugin": "CommandLine",
        "Name": name,
        "Frames": job.frames,
        "ChunkSize": str(job.chunk_size),
    }
    if job.output.endswith(("/", os.sep)):
        job_info["OutputDirectory0"] = job.output
    else:  # Deadline's viewer understands #### padding
        job_info["OutputFilename0"] = SequencePattern.parse(job.output).display
    plugin_info = {
        "Executable": job.executable,
        "Arguments": " ".join(_deadline_word(w) for w in words),
        "Shell": "default",
        "ShellExecute": "False",
        "SingleFramesOnly": "False",
        "StartupDirectory": "",
    }
    return {"job_info": job_info, "plugin_info": plugin_info}


def write_key_values(path: Path, values: Mapping[str, str]) -> None:
    """A Deadline submission file: one ``Key=Value`` per line."""
    path.write_text("".join(f"{k}={v}\n" for k, v in values.items()), encoding="utf-8")
