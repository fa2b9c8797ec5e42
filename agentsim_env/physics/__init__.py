"""Optional rigid-body physics backends.

``pymunk_backend.PymunkPlanarBackend`` resolves agent contacts with obstacle footprints and other agents in
the horizontal plane. It is imported on demand (``from agentsim_env.physics.pymunk_backend import
PymunkPlanarBackend``) and imports pymunk only when constructed, so this package imports without pymunk.
"""
