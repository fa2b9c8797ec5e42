"""Reading an arbiter's two shapes cheaply through pymunk's C layer, with a once-per-process self-check.

This module never imports pymunk: the caller (``pymunk_backend``, the project's only pymunk importer) passes
the imported module in.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any

__all__ = ["cffi_shape_getter", "shape_reader"]


@cache
def cffi_shape_getter(pm: Any) -> tuple[Any, Any] | None:
    """``(ffi, lib)`` of pymunk's C layer if reading an arbiter's shapes through it works, else None.

    ``Arbiter.shapes`` allocates two C arrays and resolves two Python handles per call (about 1 us, most of
    the filter callback); reading the two ``cpShape *`` into preallocated arrays and mapping them to slots by
    pointer costs about a third of that. It relies on pymunk internals (``pymunk._chipmunk_cffi``,
    ``Arbiter._arbiter``, ``Shape._shape``), so a tiny space checks it once per process against the public
    API; any difference falls back to ``Arbiter.shapes``.

    Args:
        pm: The imported pymunk 7 module.

    Returns:
        ``(ffi, lib)`` when the self-check passes, otherwise None.
    """
    try:
        # The package loads its cffi layer on import; reach it through the module given, not a new import.
        cffi_mod = pm._chipmunk_cffi
        ffi, lib = cffi_mod.ffi, cffi_mod.lib

        pa, pb = ffi.new("cpShape *[1]"), ffi.new("cpShape *[1]")
        space = pm.Space()
        bodies = [pm.Body(1.0, float("inf")) for _ in range(2)]
        bodies[1].position = (0.5, 0.0)
        shapes = [pm.Circle(b, 0.5) for b in bodies]
        shapes[0].collision_type, shapes[1].collision_type = 7, 8
        key = {shapes[0]._shape: shapes[0], shapes[1]._shape: shapes[1]}
        seen: list[bool] = []

        def check(arbiter: Any, space: Any, data: Any) -> None:
            lib.cpArbiterGetShapes(arbiter._arbiter, pa, pb)
            seen.append((key[pa[0]], key[pb[0]]) == tuple(arbiter.shapes) == (shapes[1], shapes[0]))

        space.add(*bodies, *shapes)
        space.on_collision(8, 7, pre_solve=check)  # handler order (8, 7): the shapes come back swapped
        space.step(0.01)
        return (ffi, lib) if seen == [True] else None
    except Exception:  # any change in those internals means: use the public API
        return None


def shape_reader(
    fast: tuple[Any, Any] | None,
) -> tuple[Callable[[Any], None], Any, Any, Callable[[Any], Any]]:
    """``(read, pa, pb, key)``: ``read(arbiter)`` puts the keys of its two shapes in ``pa[0]`` and ``pb[0]``.

    Args:
        fast: :func:`cffi_shape_getter`'s result: ``(ffi, lib)`` for the C fast path, None for the public API.

    Returns:
        ``(read, pa, pb, key)``; ``key(shape)`` is the key of a shape (its C pointer on the fast path, the
        Shape itself otherwise).
    """
    if fast is None:
        pa: Any = [None]
        pb: Any = [None]

        def read_public(arbiter: Any) -> None:
            pa[0], pb[0] = arbiter.shapes

        return read_public, pa, pb, lambda shape: shape
    ffi, lib = fast
    get = lib.cpArbiterGetShapes
    pa, pb = ffi.new("cpShape *[1]"), ffi.new("cpShape *[1]")
    return (lambda arbiter: get(arbiter._arbiter, pa, pb)), pa, pb, lambda shape: shape._shape
