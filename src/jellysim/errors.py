"""Errors that the command line maps to exit statuses (DESIGN §3)."""

from __future__ import annotations


class JellysimError(Exception):
    """Base of jellysim's own errors; ``exit_status`` is what the command line returns."""

    exit_status = 1


class InputError(JellysimError):
    """Invalid input: a scene key, a value, a file or a command-line argument (exit status 2).

    The message is at most three lines naming the key, the value and what is allowed.
    """

    exit_status = 2


class SimulationUnstable(JellysimError):
    """The simulation diverged (exit status 3); frames written before stay readable."""

    exit_status = 3

    def __init__(self, message: str, *, time: float, tentacle: int | None = None) -> None:
        super().__init__(message)
        self.time = time
        self.tentacle = tentacle


class RunInterrupted(JellysimError):
    """A run stopped by SIGINT (Ctrl-C) or SIGTERM at a frame boundary, with a checkpoint there:
    ``--resume`` continues it. Exit status 128 + the signal's number (130, 143), the shell's
    convention."""

    def __init__(self, message: str, *, signal_number: int, frame: int) -> None:
        super().__init__(message)
        self.exit_status = 128 + signal_number
        self.frame = frame


class OutputError(JellysimError):
    """The machine refused the run's output while it ran (exit status 4): the disk filled, the
    folder turned read-only, ``result.h5`` was deleted or replaced under the run. The frames
    written before stay readable and the message names them and the way to continue."""

    exit_status = 4

    def __init__(self, message: str, *, frames: int) -> None:
        super().__init__(message)
        self.frames = frames
