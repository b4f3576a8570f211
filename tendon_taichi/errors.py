"""User-facing errors (``docs/cli.md``, bad input).

Every problem a user can cause (a malformed scene, a missing file, a solve
that does not converge) raises a subclass of :class:`TendonError`; the CLI
prints its message as one line and exits non-zero.
"""


class TendonError(Exception):
    """Base class of errors that are reported to the user as one line."""


class SceneError(TendonError):
    """The scene file (or a mesh it names) is malformed or inconsistent."""


class ConvergenceError(TendonError):
    """A solver did not reach its tolerance."""


class InputError(TendonError):
    """A command-line input (file, option value) is unusable."""


class Stopped(TendonError):
    """The user stopped a run (Ctrl-C); what it finished is kept. Exit status 130."""
