"""Files written by dischargelab: atomic replacement and the output policy.

Two rules hold for every file the library or the command line writes:

* **Atomic.** The content goes to a temporary file in the destination folder,
  is flushed to disk, and replaces the destination with :func:`os.replace`. A
  crash or a full disk mid-write leaves the previous file (or none), never a
  truncated one. :func:`atomic_path` does this for any writer that wants a
  path (matplotlib, pandas, a report builder); :func:`write_bytes`,
  :func:`write_text`, :func:`write_json` and :func:`save_figure` are the
  common cases.
* **Never lose an input.** :func:`check_outputs` refuses an output that is one
  of the inputs (same resolved path or same file on disk), two outputs that are
  the same file, and an output that already exists unless ``force`` is true.
  :func:`check_inputs` refuses the same input given twice (same file, or two
  files with identical content).

Messages speak of the arguments (``force=True``); the command line turns them
into its options.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

from .errors import DataError, DischargelabError


class OutputError(DischargelabError):
    """An output file cannot be written as asked (exists, is an input, disk error)."""


class OutputExistsError(OutputError):
    """The output exists and replacing it was not allowed (``force=False``).

    Attributes
    ----------
    path : pathlib.Path
        The existing file.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        super().__init__(f"{self.path} already exists; choose another file name, or pass "
                         "force=True to replace it")


class OutputIsInputError(OutputError):
    """The output names one of the inputs (it would be overwritten).

    Attributes
    ----------
    path, input : pathlib.Path
        The output as given and the input it collides with.
    """

    def __init__(self, path: Path, input_path: Path):
        self.path, self.input = Path(path), Path(input_path)
        same = "" if str(self.path) == str(self.input) else f" (the same file as {self.input})"
        super().__init__(f"output {self.path} is also an input{same}; writing it would destroy "
                         "the input: choose another output file name")


class DuplicateInputError(DataError):
    """The same input was given twice (same file, or identical content).

    Attributes
    ----------
    first, second : pathlib.Path
    reason : str
    """

    def __init__(self, first: Path, second: Path, reason: str):
        self.first, self.second, self.reason = Path(first), Path(second), reason
        super().__init__(f"{self.first} and {self.second} are {reason}; give each input once")


# ----------------------------------------------------------------------------- policy

def _identity(path: Path):
    """(device, inode) of an existing file, else None."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


def _resolved(path: Path) -> Path:
    return Path(os.path.abspath(path)).resolve(strict=False)


def same_file(a, b) -> bool:
    """True when ``a`` and ``b`` name the same file: same resolved path or same inode."""
    a, b = Path(a), Path(b)
    if _resolved(a) == _resolved(b):
        return True
    ia, ib = _identity(a), _identity(b)
    return ia is not None and ia == ib


def _is_file_input(item) -> bool:
    return item is not None and Path(item).is_file()


def check_outputs(outputs, inputs=(), force: bool = False) -> list[Path]:
    """Apply the output policy before any work is done; returns the outputs as paths.

    Parameters
    ----------
    outputs : path or iterable of paths
        Files the caller is about to write; ``None`` entries are skipped.
    inputs : iterable of paths
        Files the caller reads. Entries that are not existing files (preset
        names, serial ports, ``None``) are skipped.
    force : bool
        Allow replacing an existing output (never an input).

    Raises
    ------
    OutputIsInputError
        An output is one of the inputs (same resolved path or same inode).
    OutputError
        Two outputs are the same file, or an output is a folder.
    OutputExistsError
        An output exists and ``force`` is false.
    """
    if isinstance(outputs, (str, os.PathLike)):
        outputs = [outputs]
    paths = [Path(p) for p in outputs if p is not None]
    files = [Path(p) for p in inputs if _is_file_input(p)]
    for k, path in enumerate(paths):
        for source in files:
            if same_file(path, source):
                raise OutputIsInputError(path, source)
        for other in paths[:k]:
            if same_file(path, other):
                raise OutputError(f"{other} and {path} are the same output file; give each "
                                  "output its own name")
        if path.is_dir():
            raise OutputError(f"output {path} is a folder; give a file name")
        if path.exists() and not force:
            raise OutputExistsError(path)
    return paths


def file_digest(path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(chunk), b""):
                h.update(block)
    except OSError as exc:
        raise DataError(f"cannot read {path}: {exc.strerror or exc}") from None
    return h.hexdigest()


def check_inputs(inputs) -> list[Path]:
    """Refuse an input given twice; returns the inputs as paths.

    Two entries are the same input when they name the same file (resolved path
    or inode) or when their contents are identical (SHA-256). Entries that are
    not existing files are passed through for the reader to report.

    Raises
    ------
    DuplicateInputError
        Naming both entries.
    """
    paths = [Path(p) for p in inputs]
    seen: list[Path] = []
    digests: dict[tuple[int, str], Path] = {}
    for path in paths:
        if not path.is_file():
            continue
        for earlier in seen:
            if same_file(path, earlier):
                reason = ("the same file" if str(path) == str(earlier)
                          else "the same file under two names")
                raise DuplicateInputError(earlier, path, reason)
        key = (path.stat().st_size, file_digest(path))
        if key in digests:
            raise DuplicateInputError(digests[key], path, "identical copies (same content)")
        digests[key] = path
        seen.append(path)
    return paths


# ----------------------------------------------------------------------------- atomic writes

@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    The temporary file keeps the destination's suffix (writers such as
    matplotlib choose the format from it). On an exception inside the block the
    temporary file is removed and ``path`` is untouched.

    Raises
    ------
    OutputError
        The folder cannot be created or written (permissions, disk full...).
    """
    path = Path(path)
    suffix = path.suffix if suffix is None else suffix
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = _create_temporary(path, suffix)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def _create_temporary(path: Path, suffix: str) -> Path:
    """An empty new file beside ``path``, with the permissions a plain ``open`` would give."""
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp{suffix}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return tmp
    raise FileExistsError(f"no free temporary name beside {path}")  # pragma: no cover


def _fsync(path: Path) -> None:
    with open(path, "rb+") as handle:
        os.fsync(handle.fileno())


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_text(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (``newline`` untranslated); returns the path."""
    return write_bytes(path, text.encode(encoding))


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON atomically; returns the path."""
    return write_text(path, json.dumps(data, indent=2) + "\n")


def save_figure(figure, path, **savefig_kwargs) -> Path:
    """Save a matplotlib figure atomically (format from the suffix of ``path``)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        figure.savefig(tmp, format=path.suffix.lstrip(".").lower() or None, **savefig_kwargs)
    return path


__all__ = ["OutputError", "OutputExistsError", "OutputIsInputError", "DuplicateInputError",
           "check_outputs", "check_inputs", "same_file", "file_digest", "atomic_path",
           "write_bytes", "write_text", "write_json", "save_figure"]
