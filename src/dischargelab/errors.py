"""Exceptions and warnings raised by dischargelab.

Library code raises these; the command line turns them into one readable line
and a non-zero exit status.
"""


class DischargelabError(Exception):
    """Base class: a problem the user can fix (bad input, impossible request)."""


class DataError(DischargelabError, ValueError):
    """Input data cannot be used (missing file, no discharge found, NaNs, ...)."""


class FitError(DischargelabError, RuntimeError):
    """The battery model could not be fitted to the data."""


class SimulationError(DischargelabError, ValueError):
    """A simulation request is impossible (cutoff above start voltage, q >= C, ...)."""


class MissingExtraError(DischargelabError, ImportError):
    """An optional dependency is missing; the message names the extra to install."""


def require(module: str, extra: str):
    """Import an optional dependency or raise :class:`MissingExtraError` naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError(
            f"{module} is not installed; install it with: pip install 'dischargelab[{extra}]'"
        ) from exc


class LogbookError(DischargelabError):
    """The logbook cannot do what was asked (unknown pack, newer database, no connection...)."""


class LogbookStorageError(LogbookError):
    """The logbook's database cannot store or answer: its disk is full, it is read-only, the
    server went away or another writer holds it too long.

    ``reason`` is one of ``"full"``, ``"read-only"``, ``"unreachable"``, ``"busy"``,
    ``"io"``. What was stored before is kept: every write is one whole transaction.
    """

    def __init__(self, message: str, reason: str = ""):
        super().__init__(message)
        self.reason = reason
