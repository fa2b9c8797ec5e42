"""The 3D web viewer: a local server (``server``), the packed state frames and log lines (``frames``), the live
viewer hook (``viewer``) and the hot-zone designer (``designer``). Pages and three.js are in ``static/``.

Needs the ``viewer`` extra (websockets); see docs/viewer.md.
"""
