"""An upload form's body (multipart/form-data) streamed to a temporary file as it arrives.

The body is fed chunk by chunk to python-multipart's streaming parser: the file part goes
straight to a file in a new private temporary folder (under the name the upload gives,
made safe), the pack name to a small bounded buffer. Nothing holds the whole upload in
memory; the logbook then reads the file once. The caller removes the folder.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..logbook.summarise import safe_file_name
from .guard import RequestRefused

#: The form's fields.
FILE_FIELD = "file"
PACK_FIELD = "pack"
#: Largest value of a text field (the pack name) and of one part's headers [bytes].
MAX_FIELD_BYTES = 4096

_USAGE = (f"send multipart/form-data with a '{FILE_FIELD}' (the log file) and a "
          f"'{PACK_FIELD}' (the pack's name) field")


def _multipart():
    try:
        from python_multipart.exceptions import FormParserError
        from python_multipart.multipart import MultipartParser, parse_options_header
    except ImportError:                                 # python-multipart < 0.0.13
        from multipart.exceptions import FormParserError
        from multipart.multipart import MultipartParser, parse_options_header
    return MultipartParser, parse_options_header, FormParserError


@dataclass
class Upload:
    """A received upload: ``path`` (named as the upload, made safe), its ``size_bytes``
    and the ``pack`` it is for."""

    path: Path
    size_bytes: int
    pack: str


class UploadReader:
    """Feed the body with :meth:`write`, then :meth:`finish` returns the :class:`Upload`.

    Parameters
    ----------
    content_type : str
        The request's Content-Type header.
    folder : path-like
        A new empty folder of our own, where the file is written.

    Raises
    ------
    RequestRefused
        400 with one line saying what is missing or malformed.
    """

    def __init__(self, content_type: str, folder):
        MultipartParser, self._options, self._error = _multipart()
        kind, params = self._options(content_type)
        if kind != b"multipart/form-data":
            raise RequestRefused(400, f"upload is {content_type or 'not typed'!r}; {_USAGE}")
        boundary = params.get(b"boundary")
        if not boundary:
            raise RequestRefused(400, f"multipart upload without a boundary; {_USAGE}")
        self.folder = Path(folder)
        self.path: Path | None = None
        self.size = 0
        self.pack = bytearray()
        self._file = None
        self._part: str | None = None      # "file", "pack" or "" (a field we ignore)
        self._headers: dict[bytes, bytes] = {}
        self._field = bytearray()
        self._value = bytearray()
        self._header_bytes = 0
        self._parser = MultipartParser(boundary, {
            "on_part_begin": self._part_begin, "on_header_field": self._header_field,
            "on_header_value": self._header_value, "on_header_end": self._header_end,
            "on_headers_finished": self._headers_finished, "on_part_data": self._part_data,
            "on_part_end": self._part_end})

    # ---------------------------------------------------------------- parser callbacks
    def _part_begin(self):
        self._headers, self._part, self._header_bytes = {}, None, 0
        self._field, self._value = bytearray(), bytearray()

    def _grow(self, buffer: bytearray, data, start, end):
        self._header_bytes += end - start
        if self._header_bytes > MAX_FIELD_BYTES:
            raise RequestRefused(400, f"a part's headers are longer than {MAX_FIELD_BYTES} "
                                      f"bytes; {_USAGE}")
        buffer += data[start:end]

    def _header_field(self, data, start, end):
        self._grow(self._field, data, start, end)

    def _header_value(self, data, start, end):
        self._grow(self._value, data, start, end)

    def _header_end(self):
        self._headers[bytes(self._field).lower()] = bytes(self._value)
        self._field, self._value = bytearray(), bytearray()

    def _headers_finished(self):
        _, options = self._options(self._headers.get(b"content-disposition", b""))
        name = options.get(b"name", b"").decode("utf-8", "replace")
        if name == FILE_FIELD:
            if self._file is not None or self.path is not None:
                raise RequestRefused(400, f"one file per upload; {_USAGE}")
            raw = options.get(b"filename", b"upload").decode("utf-8", "replace")
            self.path = self.folder / safe_file_name(raw)
            self._file = open(self.path, "xb")  # closed in _part_end or close
            self._part = FILE_FIELD
        elif name == PACK_FIELD:
            self._part = PACK_FIELD
        else:
            self._part = ""

    def _part_data(self, data, start, end):
        if self._part == FILE_FIELD:
            self._file.write(data[start:end])
            self.size += end - start
        elif self._part == PACK_FIELD:
            if len(self.pack) + end - start > MAX_FIELD_BYTES:
                raise RequestRefused(400, f"the '{PACK_FIELD}' field is longer than "
                                          f"{MAX_FIELD_BYTES} bytes")
            self.pack += data[start:end]

    def _part_end(self):
        if self._part == FILE_FIELD:
            self._close_file()

    def _close_file(self):
        if self._file is not None:
            self._file.close()
            self._file = None

    # ---------------------------------------------------------------- feeding
    def write(self, chunk: bytes) -> None:
        """Parse the next chunk of the body."""
        try:
            self._parser.write(chunk)
        except self._error:
            self.close()
            raise RequestRefused(400, f"the upload is not valid multipart/form-data; "
                                      f"{_USAGE}") from None
        except OSError as exc:
            self.close()
            raise RequestRefused(507, "no room on the server to receive the upload "
                                      f"({os.strerror(exc.errno) if exc.errno else exc}); "
                                      "try again later") from None

    def finish(self) -> Upload:
        """The upload, once the whole body was written; RequestRefused (400) when a field
        is missing, the body is cut short or the file is empty."""
        try:
            self._parser.finalize()
        except self._error:
            self.close()
            raise RequestRefused(400, f"the upload is not valid multipart/form-data; "
                                      f"{_USAGE}") from None
        cut = self._file is not None              # the file part never ended
        self.close()
        if self.path is None:
            raise RequestRefused(400, f"no '{FILE_FIELD}' field in the upload; {_USAGE}")
        if cut:
            raise RequestRefused(400, "the upload ended inside the file (the body is cut "
                                      f"short); {_USAGE}")
        if not self.size:
            raise RequestRefused(400, f"the uploaded file {self.path.name!r} is empty")
        pack = bytes(self.pack).decode("utf-8", "replace").strip()
        if not pack:
            raise RequestRefused(400, f"no '{PACK_FIELD}' field (the pack's name) in the "
                                      "upload")
        return Upload(self.path, self.size, pack)

    def close(self) -> None:
        """Close the file (the caller removes the folder)."""
        self._close_file()
