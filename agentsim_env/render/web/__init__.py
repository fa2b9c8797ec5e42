"""The 3D web viewer: a local server (``server``), the packed state frames and log lines (``frames``), the live
viewer hook (``viewer``). Pages and three.js are in ``static/``; the UAV zone designer (``agentsim_env.uav.designer``)
serves its own page with this server.

Needs the ``viewer`` extra (websockets); see docs/viewer.md.
"""
