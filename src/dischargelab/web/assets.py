"""The pages' own files (HTML, JavaScript, CSS, images), read once from the package.

They ship in the wheel as package data (``dischargelab/web/static``) and are served from a
table built here at start-up, by exact name: nothing from a CDN, and no request path ever
reaches the file system.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib.resources import files

from starlette.responses import JSONResponse, Response

#: Content type by file extension; other files are not served.
CONTENT_TYPES = {
    "html": "text/html; charset=utf-8",
    "js": "text/javascript; charset=utf-8",
    "css": "text/css; charset=utf-8",
    "svg": "image/svg+xml",
    "png": "image/png",
}
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]*\.([a-z]+)$")


@dataclass
class Assets:
    """Static files by name: ``{name: (bytes, content type)}``; pages are the ``.html`` ones."""

    files: dict

    @classmethod
    def load(cls) -> Assets:
        folder = files("dischargelab.web") / "static"
        table = {}
        for item in folder.iterdir():
            match = _NAME.match(item.name)
            if item.is_file() and match and match.group(1) in CONTENT_TYPES:
                table[item.name] = (item.read_bytes(), CONTENT_TYPES[match.group(1)])
        return cls(table)

    def static(self, name: str) -> Response:
        """A file for ``/static/NAME`` (not the pages: they have their own addresses)."""
        found = self.files.get(name)
        if found is None or name.endswith(".html"):
            return JSONResponse({"error": f"no static file named {name!r}"}, status_code=404)
        body, ctype = found
        return Response(body, media_type=ctype, headers={"Cache-Control": "no-cache"})

    def page(self, name: str) -> Response:
        body, ctype = self.files[f"{name}.html"]
        return Response(body, media_type=ctype, headers={"Cache-Control": "no-cache"})
