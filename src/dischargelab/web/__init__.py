"""The local web server: the live test bench and the logbook's pages (extra ``web``).

``dischargelab serve`` runs it. :func:`create_app` builds the ASGI application (Starlette),
:class:`~dischargelab.web.server.Server` serves it with uvicorn. The pages and their
JavaScript and CSS ship in the package (``web/static``); nothing is loaded from elsewhere.
Importing :mod:`dischargelab` does not import this package.
"""

from __future__ import annotations


def create_app(*args, **kwargs):
    """Build the application; see :func:`dischargelab.web.app.create_app`."""
    from .app import create_app as _create_app

    return _create_app(*args, **kwargs)


__all__ = ["create_app"]
