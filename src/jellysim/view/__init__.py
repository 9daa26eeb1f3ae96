"""``jellysim view DIR``: a local web page that plays a result in the browser (docs/viewer.md).

A standard-library HTTP server (:mod:`jellysim.view.server`) serves the page under
``static/``, three.js from the installed npm package (``web/node_modules``), the result's
metadata as JSON and its frames as little-endian float32 chunks; the drawn tentacles are
interpolated on request by :func:`jellysim.interpolation.interpolate_result`. What one session
may cost the machine is bounded by :class:`ViewLimits`, and only the page, at the address
printed with the session's token, gets the data.
"""

from jellysim.view.server import ResultData, ViewLimits, ViewServer, find_web_modules, serve

__all__ = ["ResultData", "ViewLimits", "ViewServer", "find_web_modules", "serve"]
