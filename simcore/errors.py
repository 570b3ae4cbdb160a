"""Exceptions for mistakes in what the user asked for.

Every layer may import this module (it imports nothing of sunsim). The
command line prints a :class:`UserError` as one line and exits with status 2;
any other exception is a bug in sunsim and keeps its traceback. The
subclasses also derive from the built-in exception a Python caller would
expect (``ValueError``, ``FileNotFoundError``, ...), so library code that
catches those keeps working.
"""


class UserError(Exception):
    """A mistake in the user's input: the message says what was wrong and what to do."""


class InvalidInputError(UserError, ValueError):
    """A value, option or file content that cannot be used."""


class InputNotFoundError(UserError, FileNotFoundError):
    """A file the user named does not exist."""


class OutputError(UserError, PermissionError):
    """An output path that cannot be written (missing folder, no permission, a folder, in use)."""


class OutputFolderMissingError(UserError, FileNotFoundError):
    """The folder of an output path does not exist."""


class OutputIsAFolderError(UserError, IsADirectoryError):
    """An output path names a folder."""


class MissingExtraError(UserError, ImportError):
    """An optional dependency (a pip extra) that a command needs is not installed."""


class ClusterError(UserError, RuntimeError):
    """The Dask cluster cannot do the work: no workers, an unreachable scheduler, a worker that keeps dying."""
