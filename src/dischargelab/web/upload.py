"""An upload form's body (multipart/form-data) parsed in memory.

The body was already read under the size limit; it is parsed with python-multipart's
streaming parser into memory only, so an upload never touches the disk before the logbook
stores it.
"""

from __future__ import annotations

from ..logbook.summarise import safe_file_name
from .guard import RequestRefused

#: The form's fields.
FILE_FIELD = "file"
PACK_FIELD = "pack"

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


def parse_upload(content_type: str, body: bytes) -> tuple[str, bytes, str]:
    """``(file name, file bytes, pack name)`` from a multipart body; RequestRefused (400)
    with one line saying what is missing or malformed."""
    MultipartParser, parse_options_header, FormParserError = _multipart()
    kind, params = parse_options_header(content_type)
    if kind != b"multipart/form-data":
        raise RequestRefused(400, f"upload is {content_type or 'not typed'!r}; {_USAGE}")
    boundary = params.get(b"boundary")
    if not boundary:
        raise RequestRefused(400, f"multipart upload without a boundary; {_USAGE}")
    parts: list[dict] = []
    state: dict = {}

    def on_part_begin():
        state["part"] = {"headers": {}, "data": bytearray()}
        state["field"], state["value"] = b"", b""

    def on_header_field(data, start, end):
        state["field"] += data[start:end]

    def on_header_value(data, start, end):
        state["value"] += data[start:end]

    def on_header_end():
        state["part"]["headers"][state["field"].lower()] = state["value"]
        state["field"], state["value"] = b"", b""

    def on_part_data(data, start, end):
        state["part"]["data"] += data[start:end]

    def on_part_end():
        parts.append(state.pop("part"))

    callbacks = {"on_part_begin": on_part_begin, "on_header_field": on_header_field,
                 "on_header_value": on_header_value, "on_header_end": on_header_end,
                 "on_part_data": on_part_data, "on_part_end": on_part_end}
    parser = MultipartParser(boundary, callbacks)
    try:
        parser.write(body)
        parser.finalize()
    except FormParserError:
        raise RequestRefused(400, f"the upload is not valid multipart/form-data; {_USAGE}"
                             ) from None
    file_name, data, pack = None, None, None
    for part in parts:
        disposition = part["headers"].get(b"content-disposition", b"")
        _, options = parse_options_header(disposition)
        name = options.get(b"name", b"").decode("utf-8", "replace")
        if name == FILE_FIELD:
            raw_name = options.get(b"filename", b"upload").decode("utf-8", "replace")
            file_name = safe_file_name(raw_name)
            data = bytes(part["data"])
        elif name == PACK_FIELD:
            pack = bytes(part["data"]).decode("utf-8", "replace").strip()
    if data is None:
        raise RequestRefused(400, f"no '{FILE_FIELD}' field in the upload; {_USAGE}")
    if not data:
        raise RequestRefused(400, f"the uploaded file {file_name!r} is empty")
    if not pack:
        raise RequestRefused(400, f"no '{PACK_FIELD}' field (the pack's name) in the upload")
    return file_name, data, pack
