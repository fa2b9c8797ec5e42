"""Tests for the optional pymunk planar physics backend."""

from __future__ import annotations

import copy
import pickle
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pymunk")

from agentsim_env.physics import pymunk_backend  # noqa: E402
from agentsim_env.physics.pymunk_backend import PhysicsContacts, PymunkPlanarBackend  # noqa: E402

DT = 0.1
R = 0.5
# A wall: box at x = 5 (faces at 4.8 and 5.2), 40 m long in y, from z = 0 to z = 10.
WALL = ([0], [[5.0, 0.0, 5.0]], [[0.2, 20.0, 5.0]], [0])
NO_OBJ = (np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int32))


def make(n: int = 1, obstacles=WALL, world_id=None, n_worlds: int = 1, radius: float = R) -> PymunkPlanarBackend:
    wid = np.zeros(n, dtype=np.int64) if world_id is None else np.asarray(world_id)
    return PymunkPlanarBackend(np.full(n, radius), wid, n_worlds, *obstacles)


def run(be: PymunkPlanarBackend, pos: np.ndarray, vel: np.ndarray, steps: int, online=None):
    """Step with constant commanded velocity; returns the xy track (steps, S, 2) and all contact rows."""
    pos = np.array(pos, dtype=np.float64)
    online = np.ones(pos.shape[0], dtype=bool) if online is None else online
    track, rows = [], []
    for _ in range(steps):
        xy, _, c = be.step(pos, vel, online, DT)
        pos[:, :2] = xy
        track.append(xy)
        rows.extend(zip(c.agent.tolist(), c.other_agent.tolist(), c.obj.tolist(), strict=True))
    return np.array(track), rows


def test_slides_along_wall_and_never_crosses():
    be = make()
    track, rows = run(be, [[0.0, 0.0, 2.0]], np.array([[3.0, 1.0, 0.0]]), 100)
    x, y = track[:, 0, 0], track[:, 0, 1]
    assert x.max() < 4.8 - R + 0.1  # never through the wall's near face (small solver overlap allowed)
    assert x[-1] > 4.8 - R - 0.05  # pressed against it
    assert y[-1] == pytest.approx(10.0, abs=0.3)  # slid along it at the tangential speed
    assert rows == [(0, -1, 0)]  # one contact, reported when it began
    _, vel, _ = be.step(np.array([[x[-1], y[-1], 2.0]]), np.array([[3.0, 1.0, 0.0]]), np.array([True]), DT)
    np.testing.assert_allclose(vel, [[0.0, 1.0]], atol=1e-6)  # normal component removed


@pytest.mark.parametrize(
    ("z", "blocked"),
    [(10.6, False), (10.4, True), (-0.6, False), (5.0, True)],  # wall spans z in [0, 10], r = 0.5
)
def test_altitude_decides_obstacle_contact(z, blocked):
    track, rows = run(make(), [[0.0, 0.0, z]], np.array([[3.0, 0.0, 0.0]]), 40)
    if blocked:
        assert track[:, 0, 0].max() < 4.4 and rows == [(0, -1, 0)]
    else:
        assert track[-1, 0, 0] == pytest.approx(12.0) and rows == []


@pytest.mark.parametrize("kind", [1, 2])
def test_round_footprints_block_at_radius_sum(kind):
    # Cylinder (radius 1, half-height 2) or sphere (radius 1) centred at (5, 0, 2).
    be = make(obstacles=([kind], [[5.0, 0.0, 2.0]], [[1.0, 1.0, 2.0]], [0]))
    track, rows = run(be, [[0.0, 0.0, 2.0]], np.array([[2.0, 0.0, 0.0]]), 40)
    assert track[-1, 0, 0] == pytest.approx(5.0 - 1.0 - R, abs=0.03)
    assert rows == [(0, -1, 0)]
    # A sphere spans centre_z +- radius = [1, 3]: an agent whose bottom is above 3 passes over it.
    if kind == 2:
        be = make(obstacles=([2], [[5.0, 0.0, 2.0]], [[1.0, 1.0, 1.0]], [0]))
        track, rows = run(be, [[0.0, 0.0, 3.6]], np.array([[2.0, 0.0, 0.0]]), 40)
        assert track[-1, 0, 0] == pytest.approx(8.0) and rows == []


def test_agent_contact_reported_once_and_overlap_small():
    be = make(2, obstacles=NO_OBJ)
    pos = np.array([[-3.0, 0.0, 5.0], [3.0, 0.1, 5.0]])
    vel = np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 0.0]])
    track, rows = run(be, pos, vel, 50)
    gap = np.linalg.norm(track[:, 0] - track[:, 1], axis=1)
    assert gap.min() > 2 * R - 0.05
    assert rows == [(0, 1, -1)]


def test_agents_at_different_altitudes_pass_through():
    be = make(2, obstacles=NO_OBJ)
    pos = np.array([[-3.0, 0.0, 5.0], [3.0, 0.0, 6.1]])  # |dz| = 1.1 > r_a + r_b
    vel = np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 0.0]])
    track, rows = run(be, pos, vel, 30)
    np.testing.assert_allclose(track[-1], [[3.0, 0.0], [-3.0, 0.0]], atol=1e-9)
    assert rows == []


def test_crowd_pairs_unique_and_overlap_bounded():
    rng = np.random.default_rng(3)
    n = 60
    be = make(n, obstacles=NO_OBJ)
    pos = np.zeros((n, 3))
    pos[:, :2] = rng.uniform(-10.0, 10.0, (n, 2))
    for _ in range(60):
        d = -pos[:, :2]
        vel = np.zeros((n, 3))
        vel[:, :2] = 2.0 * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        xy, _, c = be.step(pos, vel, np.ones(n, bool), DT)
        pos[:, :2] = xy
        keys = list(zip(c.agent.tolist(), c.other_agent.tolist(), c.obj.tolist(), strict=True))
        assert len(keys) == len(set(keys))
        assert np.all(c.agent < c.other_agent) and np.all(c.obj == -1)
        assert c.agent.dtype == np.int64
    dist = np.linalg.norm(pos[:, None, :2] - pos[None, :, :2], axis=2) + np.eye(n) * 10
    assert dist.min() > 2 * R - 0.1


def test_worlds_do_not_interact():
    # Same coordinates, different worlds; the wall exists only in world 1.
    be = make(2, obstacles=([0], [[5.0, 0.0, 5.0]], [[0.2, 20.0, 5.0]], [1]), world_id=[0, 1], n_worlds=2)
    pos = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    track, rows = run(be, pos, np.array([[3.0, 0.0, 0.0], [3.0, 0.0, 0.0]]), 30)
    assert track[-1, 0, 0] == pytest.approx(9.0)  # world 0 has no wall and no overlapping neighbour
    assert track[-1, 1, 0] < 4.4
    assert rows == [(1, -1, 0)]


def test_offline_agents_frozen_and_contactless():
    be = make(2)
    pos = np.array([[0.0, 0.0, 2.0], [5.0, 0.0, 2.0]])  # slot 1 sits inside the wall, offline
    vel = np.array([[3.0, 0.0, 0.0], [1.0, 2.0, 0.0]])
    online = np.array([True, False])
    for _ in range(10):
        xy, v, c = be.step(pos, vel, online, DT)
        np.testing.assert_array_equal(xy[1], pos[1, :2])
        np.testing.assert_array_equal(v[1], vel[1, :2])
        assert 1 not in c.agent.tolist() and 1 not in c.other_agent.tolist()
        pos[:, :2] = xy
    # Back online away from the wall, it collides again.
    pos[1] = [xy[0, 0] + 0.9, xy[0, 1], 2.0]
    _, _, c = be.step(pos, np.zeros((2, 3)), np.array([True, True]), DT)
    assert (0, 1, -1) in zip(c.agent.tolist(), c.other_agent.tolist(), c.obj.tolist(), strict=True)


def test_offline_rows_may_hold_nan():
    pos = np.array([[0.0, 0.0, 2.0], [np.nan, np.nan, np.nan]])
    vel = np.array([[1.0, 0.0, 0.0], [np.nan, np.nan, np.nan]])
    xy, v, c = make(2).step(pos, vel, np.array([True, False]), DT)
    assert np.isnan(xy[1]).all() and np.isnan(v[1]).all() and len(c) == 0
    np.testing.assert_allclose(xy[0], [0.1, 0.0])


def test_add_obstacles_at_run_time():
    be = make(obstacles=NO_OBJ)
    ids = be.add_obstacles(np.array([1], np.int8), [[4.0, 0.0, 1.0]], [[0.5, 0.5, 1.0]], [0])
    assert ids.tolist() == [0] and be.n_obstacles == 1
    track, rows = run(be, [[0.0, 0.0, 1.0]], np.array([[2.0, 0.0, 0.0]]), 30)
    assert track[-1, 0, 0] == pytest.approx(3.0, abs=0.03) and rows == [(0, -1, 0)]


def _scene() -> tuple[PymunkPlanarBackend, np.ndarray, np.ndarray]:
    be = make(3, world_id=[0, 0, 1], n_worlds=2)
    pos = np.array([[0.0, 0.0, 2.0], [0.0, 3.0, 2.0], [1.0, 1.0, 2.0]])
    vel = np.array([[3.0, 0.5, 0.0], [2.0, -0.5, 0.0], [1.0, 0.0, 0.0]])
    return be, pos, vel


def test_pickle_round_trip_gives_same_next_steps():
    be, pos, vel = _scene()
    online = np.array([True, True, False])
    run(be, pos, vel, 3, online)  # contact-free so far
    clones = [pickle.loads(pickle.dumps(be)), copy.deepcopy(be)]
    began = 0
    for _ in range(20):  # the wall contact and an agent contact begin during these steps
        xa, va, ca = be.step(pos, vel, online, DT)
        for clone in clones:
            xb, vb, cb = clone.step(pos, vel, online, DT)
            np.testing.assert_array_equal(xa, xb)
            np.testing.assert_array_equal(va, vb)
            for f in ("agent", "other_agent", "obj"):
                np.testing.assert_array_equal(getattr(ca, f), getattr(cb, f))
        began += len(ca)
        pos[:, :2] = xa
    assert began >= 1


def test_pickle_keeps_contact_memory():
    be = make()
    pos = np.array([[3.0, 0.0, 2.0]])
    vel = np.array([[3.0, 0.0, 0.0]])
    _, rows = run(be, pos, vel, 10)
    assert rows == [(0, -1, 0)]
    clone = pickle.loads(pickle.dumps(be))
    pos[0, 0] = 4.3
    xa, _, ca = be.step(pos, vel, np.array([True]), DT)
    xb, _, cb = clone.step(pos, vel, np.array([True]), DT)
    assert len(ca) == len(cb) == 0  # the resting contact is not reported again
    np.testing.assert_allclose(xa, xb, atol=0.02)  # warm-start state is rebuilt, not copied


def test_reset_matches_fresh_backend():
    be, pos, vel = _scene()
    run(be, pos, vel, 25)
    be.reset()
    fresh, _, _ = _scene()
    ta, ra = run(be, pos, vel, 25)
    tb, rb = run(fresh, pos, vel, 25)
    np.testing.assert_array_equal(ta, tb)
    assert ra == rb


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"radius": np.ones((2, 1))}, "radius"),
        ({"radius": np.array([0.5, -1.0])}, "radius"),
        ({"world_id": np.zeros(3, np.int64)}, "world_id"),
        ({"world_id": np.array([0, 2])}, "world_id"),
        ({"n_worlds": 0}, "n_worlds"),
        ({"obj_centre": np.zeros((1, 2))}, "obj_centre"),
        ({"obj_half": np.zeros((1, 3))}, "obj_half"),
        ({"obj_kind": np.array([3])}, "obj_kind"),
        ({"obj_world": np.array([5])}, "obj_world"),
        ({"substeps": 0}, "substeps"),
    ],
)
def test_bad_constructor_input_names_argument(kwargs, name):
    args = {
        "radius": np.full(2, R),
        "world_id": np.zeros(2, np.int64),
        "n_worlds": 1,
        "obj_kind": np.array([0]),
        "obj_centre": np.array([[5.0, 0.0, 5.0]]),
        "obj_half": np.array([[0.2, 20.0, 5.0]]),
        "obj_world": np.array([0]),
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        PymunkPlanarBackend(**args)


@pytest.mark.parametrize(
    ("pos", "vel", "online", "dt", "name"),
    [
        (np.zeros((2, 2)), np.zeros((2, 3)), np.ones(2, bool), DT, "pos"),
        (np.zeros((2, 3)), np.zeros(2), np.ones(2, bool), DT, "desired_vel"),
        (np.zeros((2, 3)), np.zeros((2, 3)), np.ones(3, bool), DT, "online"),
        (np.zeros((2, 3)), np.zeros((2, 3)), np.ones(2), DT, "online"),
        (np.zeros((2, 3)), np.zeros((2, 3)), np.ones(2, bool), 0.0, "dt"),
        (np.full((2, 3), 6.0e4), np.zeros((2, 3)), np.ones(2, bool), DT, "pos"),
        (np.array([[0.0, 0.0, 1.0], [0.0, np.nan, 1.0]]), np.zeros((2, 3)), np.ones(2, bool), DT, "pos"),
        (
            np.zeros((2, 3)),
            np.array([[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]]),
            np.ones(2, bool),
            DT,
            "desired_vel",
        ),
    ],
)
def test_bad_step_input_names_argument(pos, vel, online, dt, name):
    with pytest.raises(ValueError, match=name):
        make(2).step(pos, vel, online, dt)


def test_empty_contacts_type():
    _, _, c = make(obstacles=NO_OBJ).step(np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1, bool), DT)
    assert isinstance(c, PhysicsContacts) and len(c) == 0 and c.obj.dtype == np.int64
    assert not c.agent.flags.writeable  # the shared empty instance cannot be corrupted by a caller


def _crowd(seed: int, steps: int = 40):
    """Three worlds of 30 agents around a wall and a cylinder, pulled to the centre at spread altitudes; slots
    toggle online every 8 steps and offline rows hold NaN. Yields each step's inputs."""
    rng = np.random.default_rng(seed)
    n, n_w = 90, 3
    obstacles = (
        [0, 1, 1],
        [[4.0, 0.0, 3.0], [-3.0, 2.0, 2.0], [0.0, -3.0, 2.0]],
        [[0.2, 3.0, 3.0], [1.0, 1.0, 2.0], [1.0, 1.0, 2.0]],
        [0, 1, 2],
    )
    be_args = (np.full(n, R), np.repeat(np.arange(n_w), n // n_w), n_w, *obstacles)
    pos = np.zeros((n, 3))
    pos[:, :2] = rng.uniform(-8.0, 8.0, (n, 2))
    pos[:, 2] = rng.uniform(0.0, 6.0, n)
    online = np.ones(n, bool)
    inputs = []
    for t in range(steps):
        if t % 8 == 7:
            online = rng.random(n) < 0.8
        d = -pos[:, :2]
        vel = np.zeros((n, 3))
        vel[:, :2] = 3.0 * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        p = pos.copy()
        p[~online] = np.nan
        inputs.append((p, vel, online.copy()))
        pos[:, :2] += vel[:, :2] * DT  # the inputs do not depend on the backend's answers
    return be_args, inputs


def _run_crowd(be_args, inputs):
    be = PymunkPlanarBackend(*be_args)
    out = []
    for p, vel, on in inputs:
        xy, v, c = be.step(p, vel, on, DT)
        out.append((xy, v, c.agent, c.other_agent, c.obj))
    return out


def test_step_unchecked_matches_step_and_writes_online_rows_only():
    be_args, inputs = _crowd(5)
    ref = _run_crowd(be_args, inputs)
    assert sum(len(r[2]) for r in ref) >= 5  # agent and obstacle contacts do begin
    be = PymunkPlanarBackend(*be_args)
    for (p, vel, on), (xy, v, a, b, o) in zip(inputs, ref, strict=True):
        pos = p.copy()  # the output aliases the input, as in the world
        out_vel = np.full((len(on), 3), 7.0)
        c = be.step_unchecked(pos, vel[:, :2].copy(), on, DT, pos, out_vel)
        np.testing.assert_array_equal(pos[on, :2], xy[on])
        np.testing.assert_array_equal(out_vel[on, :2], v[on])
        assert np.isnan(pos[~on]).all() and (out_vel[~on] == 7.0).all() and (out_vel[:, 2] == 7.0).all()
        np.testing.assert_array_equal(pos[:, 2], p[:, 2])
        for got, want in zip((c.agent, c.other_agent, c.obj), (a, b, o), strict=True):
            np.testing.assert_array_equal(got, want)


def test_public_arbiter_api_gives_identical_results(monkeypatch):
    # The callbacks read an arbiter's shapes through pymunk's C layer when its self-check passes (it should
    # on pymunk 7.3); the public Arbiter.shapes fallback must give the same trajectories and contacts.
    assert pymunk_backend._cffi_shape_getter() is not None
    be_args, inputs = _crowd(6, steps=24)
    fast = _run_crowd(be_args, inputs)
    monkeypatch.setattr(pymunk_backend, "_cffi_shape_getter", lambda: None)
    public = _run_crowd(be_args, inputs)
    for f, p in zip(fast, public, strict=True):
        for x, y in zip(f, p, strict=True):
            np.testing.assert_array_equal(x, y)
    assert sum(len(f[2]) for f in fast) >= 1


def test_extend_obstacles_only_appends():
    be = make(obstacles=WALL)
    kind, centre, half, world = (
        [0, 1],
        [[5.0, 0.0, 5.0], [2.0, 0.0, 1.0]],
        [[0.2, 20.0, 5.0], [0.5, 0.5, 1.0]],
        [0, 0],
    )
    assert be.extend_obstacles(kind[:1], centre[:1], half[:1], world[:1]) and be.n_obstacles == 1  # no change
    assert be.extend_obstacles(kind, centre, half, world) and be.n_obstacles == 2
    track, rows = run(be, [[0.0, 0.0, 1.0]], np.array([[2.0, 0.0, 0.0]]), 20)
    assert track[-1, 0, 0] == pytest.approx(1.0, abs=0.03) and rows == [(0, -1, 1)]  # the new cylinder blocks
    moved = [[5.5, 0.0, 5.0], [2.0, 0.0, 1.0], [9.0, 0.0, 1.0]]
    assert not be.extend_obstacles([0, 1, 1], moved, half + [[0.5, 0.5, 1.0]], [0, 0, 0])
    assert not be.extend_obstacles(kind[:1], centre[:1], half[:1], world[:1])  # fewer: one was removed
    assert be.n_obstacles == 2


def test_dt_may_change_between_steps():
    be = make(obstacles=NO_OBJ)
    pos, vel, on = np.array([[0.0, 0.0, 1.0]]), np.array([[2.0, 0.0, 0.0]]), np.ones(1, bool)
    for dt in (0.1, 0.05, 0.05, 0.2):
        xy, _, _ = be.step(pos, vel, on, dt)
        assert xy[0, 0] == pytest.approx(pos[0, 0] + 2.0 * dt)
        pos[0, :2] = xy[0]


def test_slot_going_offline_is_parked_at_rest():
    be = make(2, obstacles=NO_OBJ)
    pos, vel = np.array([[0.0, 0.0, 1.0], [3.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0], [-1.0, 0.5, 0.0]])
    be.step(pos, vel, np.array([True, True]), DT)
    be.step(pos, vel, np.array([True, False]), DT)
    body = be._agent_shapes[1].body  # white box: where pymunk keeps the offline body
    assert body.position.y < -1.0e8 and tuple(body.velocity) == (0.0, 0.0)
    xy, _, _ = be.step(pos, vel, np.array([True, True]), DT)  # back online, from the given position
    np.testing.assert_allclose(xy[1], [2.9, 0.05])


def test_package_import_does_not_import_pymunk():
    code = (
        "import sys, agentsim_env.physics, agentsim_env.physics.pymunk_backend\n"
        "assert 'pymunk' not in sys.modules, 'pymunk imported eagerly'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_missing_pymunk_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "pymunk", None)
    monkeypatch.setitem(sys.modules, "pymunk.batch", None)
    with pytest.raises(ImportError, match='pip install "pymunk>=7,<8"'):
        make()
