"""Exit codes and the exceptions that map to them (published in the README)."""

from __future__ import annotations

EXIT_OK = 0
EXIT_RUNTIME = 1
EXIT_USAGE = 2
EXIT_INPUT = 3
EXIT_OUTPUT_EXISTS = 4
EXIT_SIGINT = 130
EXIT_SIGTERM = 143


class SvgfError(Exception):
    """An error with a one-line message and an exit code."""

    exit_code = EXIT_RUNTIME

    def __init__(self, message: str, path: str | None = None) -> None:
        self.path = path
        super().__init__(f"{path}: {message}" if path else message)


class InputError(SvgfError):
    """Missing, unreadable, corrupt or inconsistent input (a frame, a channel, a scene)."""

    exit_code = EXIT_INPUT


class OutputExistsError(SvgfError):
    """An output exists and neither --overwrite nor --skip-existing was given."""

    exit_code = EXIT_OUTPUT_EXISTS


class UsageError(SvgfError):
    """Options that contradict each other or name something that cannot be."""

    exit_code = EXIT_USAGE
