"""Request bodies read under a size limit, and the one JSON error shape of the API."""

from __future__ import annotations

import json

from starlette.requests import Request
from starlette.responses import JSONResponse

from .guard import RequestRefused

#: Largest JSON body of a form post (start settings, fit request) [bytes].
MAX_JSON_BYTES = 64 * 1024


def error(status: int, message: str) -> JSONResponse:
    """A JSON error response ``{"error": message}``."""
    return JSONResponse({"error": message}, status_code=status)


def check_length(request: Request, limit: int, what: str = "request body") -> None:
    """Refuse (413) a body whose Content-Length is over ``limit`` bytes, before reading it."""
    length = request.headers.get("content-length")
    if length is None:
        return
    try:
        declared = int(length)
    except ValueError:
        raise RequestRefused(400, "Content-Length is not a number") from None
    if declared > limit:
        raise RequestRefused(413, f"{what} of {declared} bytes is over the limit of "
                                  f"{limit} bytes")


async def read_body(request: Request, limit: int, what: str = "request body") -> bytes:
    """The request body, refusing (413) more than ``limit`` bytes before reading them all."""
    check_length(request, limit, what)
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise RequestRefused(413, f"{what} is over the limit of {limit} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


async def read_json(request: Request) -> dict:
    body = await read_body(request, MAX_JSON_BYTES, "JSON body")
    if not body.strip():
        return {}
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise RequestRefused(400, "the body is not valid JSON") from None
    if not isinstance(data, dict):
        raise RequestRefused(400, "the body must be a JSON object")
    return data
