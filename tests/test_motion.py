"""Tests for agentsim_env.motion: closed forms, path following, limits, kernel vs reference, decoders."""

from __future__ import annotations

import pickle
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agentsim_env.motion import (
    CIRCULAR,
    HOLD,
    LINEAR,
    PARABOLIC,
    PATH,
    PRIMITIVE_ACTION_DIM,
    SEL_CIRCULAR,
    SEL_GOTO,
    SEL_KEEP,
    SEL_LINEAR,
    SEL_PARABOLIC,
    SEL_VELOCITY,
    VELOCITY,
    VELOCITY_ACTION_DIM,
    MotionLimits,
    MotionState,
    decode_primitive,
    decode_velocity,
    integrate,
    selector_action,
    set_circular,
    set_hold,
    set_linear,
    set_parabolic,
    set_path,
    set_velocity,
)
from tests.reference.motion import integrate_reference

DT = 0.1
LIMITS = MotionLimits(
    max_speed=8.0, max_accel=4.0, max_radius=30.0, max_duration=5.0, z_min=5.0, z_max=40.0, max_omega=1.0
)


@dataclass
class World:
    """The world-owned arrays the integrator works on."""

    pos: np.ndarray
    vel: np.ndarray
    heading: np.ndarray
    max_speed: np.ndarray
    max_accel: np.ndarray
    online: np.ndarray

    @classmethod
    def make(cls, n: int, pos: np.ndarray | None = None, max_speed: float = 10.0, max_accel: float = 5.0) -> World:
        return cls(
            pos=np.zeros((n, 3)) if pos is None else np.array(pos, dtype=np.float64),
            vel=np.zeros((n, 3)),
            heading=np.zeros(n),
            max_speed=np.full(n, max_speed),
            max_accel=np.full(n, max_accel),
            online=np.ones(n, dtype=bool),
        )

    def copy(self) -> World:
        return World(
            *(a.copy() for a in (self.pos, self.vel, self.heading, self.max_speed, self.max_accel, self.online))
        )

    def step(self, ms: MotionState, fn=integrate) -> None:
        fn(ms, self.pos, self.vel, self.heading, self.max_speed, self.max_accel, self.online, DT)


def wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# ---------------------------------------------------------------- state


def test_create_reset_copy_pickle():
    ms = MotionState.create(4, max_waypoints=5)
    assert ms.n_slots == 4 and ms.max_waypoints == 5
    assert (ms.kind == HOLD).all() and ms.kind.dtype == np.int8 and ms.params.shape == (4, 10)
    w = World.make(4, pos=np.ones((4, 3)))
    set_linear(ms, [1, 2], w.pos, [1.0, 0, 0], 2.0, 3.0)
    c = ms.copy()
    c.params[1, 0] = 99.0
    assert ms.params[1, 0] == 1.0
    r = pickle.loads(pickle.dumps(ms))
    assert all(np.array_equal(getattr(r, f), getattr(ms, f)) for f in ("kind", "params", "t", "waypoints"))
    ms.reset([1])
    assert ms.kind[1] == HOLD and ms.kind[2] == LINEAR and not ms.params[1].any()
    with pytest.raises(ValueError, match="n_slots"):
        MotionState.create(-1)
    with pytest.raises(ValueError, match="max_waypoints"):
        MotionState.create(3, max_waypoints=0)


# ---------------------------------------------------------------- closed forms


def test_linear_closed_form_then_hold():
    p0 = np.array([[0.0, 0, 10], [5, 5, 5], [1, 2, 3]])
    w = World.make(3, pos=p0)
    ms = MotionState.create(3)
    d = np.array([[1.0, 0, 0], [0, 3, 4], [1, 1, 0]])
    speed, dur = np.array([2.0, 5.0, 30.0]), np.array([1.0, 2.5, 10.0])
    set_linear(ms, np.arange(3), w.pos, d, speed, dur)
    v = d / np.linalg.norm(d, axis=1)[:, None] * np.minimum(speed, 10.0)[:, None]  # slot 2 clipped to max_speed
    for n in range(1, 121):
        w.step(ms)
        t = n * DT
        expect = p0 + v * np.minimum(t, dur)[:, None]
        np.testing.assert_allclose(w.pos, expect, atol=1e-9, rtol=0)
        finished = t >= dur - 1e-9
        np.testing.assert_array_equal(ms.done, finished)
        np.testing.assert_allclose(w.vel, np.where(finished[:, None], 0.0, v), atol=1e-12)
        assert np.linalg.norm(w.vel, axis=1).max() <= 10.0 + 1e-9
    np.testing.assert_allclose(w.heading, np.arctan2(v[:, 1], v[:, 0]))  # kept after stopping
    assert ms.done[0] and ms.kind[0] == LINEAR


def test_linear_zero_direction_stays():
    w = World.make(1, pos=[[1.0, 2.0, 3.0]])
    ms = MotionState.create(1)
    set_linear(ms, [0], w.pos, [0.0, 0.0, 0.0], 5.0, 1.0)
    for _ in range(5):
        w.step(ms)
    np.testing.assert_array_equal(w.pos, [[1.0, 2.0, 3.0]])


def test_circular_closed_form_radius_and_rate():
    p0 = np.array([[13.0, 0, 0], [0, -4, 7], [2, 2, 2]])
    w = World.make(3, pos=p0, max_speed=10.0)
    ms = MotionState.create(3)
    centre = np.array([[10.0, 0.0], [0.0, 0.0], [2.0, 2.0]])  # slot 2 starts on the centre: phase 0
    radius, omega, alt = np.array([3.0, 20.0, 5.0]), np.array([0.7, -1.0, 0.2]), np.array([10.0, 20.0, 3.0])
    set_circular(ms, np.arange(3), w.pos, centre, radius, omega, alt)
    phase0 = np.array([0.0, -np.pi / 2, 0.0])
    w_eff = np.array([0.7, -0.5, 0.2])  # slot 1: 20 m * 1 rad/s > 10 m/s, so omega is clipped to 0.5
    prev = None
    for _ in range(2000):
        w.step(ms)
        rel = w.pos[:, :2] - centre
        np.testing.assert_allclose(np.linalg.norm(rel, axis=1), radius, atol=1e-9)
        np.testing.assert_allclose(w.pos[:, 2], alt)
        ang = np.arctan2(rel[:, 1], rel[:, 0])
        if prev is not None:
            np.testing.assert_allclose(wrap(ang - prev), w_eff * DT, atol=1e-9)
        prev = ang
        np.testing.assert_allclose(np.linalg.norm(w.vel, axis=1), radius * np.abs(w_eff), atol=1e-9)
    t = 2000 * DT
    a = phase0 + w_eff * t
    expect = np.c_[centre[:, 0] + radius * np.cos(a), centre[:, 1] + radius * np.sin(a), alt]
    np.testing.assert_allclose(w.pos, expect, atol=1e-9, rtol=0)
    np.testing.assert_allclose(wrap(w.heading - (a + np.sign(w_eff) * np.pi / 2)), 0.0, atol=1e-9)
    assert not ms.done.any()


def test_parabolic_closed_form_then_rests_on_ground():
    p0 = np.array([[0.0, 0, 20], [3, 4, 0.5], [0, 0, 1]])
    v0 = np.array([[3.0, -1, 4], [0, 0, 0], [30, 0, 40]])  # slot 2 faster than max_speed: not clipped
    g = np.array([9.81, 9.81, 3.0])
    w = World.make(3, pos=p0)
    ms = MotionState.create(3)
    set_parabolic(ms, np.arange(3), w.pos, v0, g)
    t_land = (v0[:, 2] + np.sqrt(v0[:, 2] ** 2 + 2 * g * p0[:, 2])) / g
    for n in range(1, 301):
        w.step(ms)
        t = n * DT
        flying = t < t_land
        te = np.minimum(t, t_land)
        expect = p0 + v0 * te[:, None]
        expect[:, 2] = np.where(flying, p0[:, 2] + v0[:, 2] * t - 0.5 * g * t * t, 0.0)
        np.testing.assert_allclose(w.pos, expect, atol=1e-9, rtol=0)
        np.testing.assert_array_equal(ms.done, ~flying)
        v_expect = np.where(flying[:, None], v0 - np.outer(g * t, [0, 0, 1]), 0.0)
        np.testing.assert_allclose(w.vel, v_expect, atol=1e-9)
    assert (w.pos[:, 2] == 0.0).all() and ms.done.all()


# ---------------------------------------------------------------- path and velocity


def run_path(loop: bool, steps: int, arrival: float = 0.0):
    wps = np.array([[10.0, 0, 5], [10, 10, 5], [0, 10, 5], [0, 0, 5]])
    w = World.make(1, pos=[[0.0, 0.0, 5.0]], max_speed=3.0)
    ms = MotionState.create(1)
    set_path(ms, [0], wps[None], speed=4.0, arrival_radius=arrival, loop=loop)  # speed clipped to 3
    visits, track = [], []
    for _ in range(steps):
        before, was_done = int(ms.wp_index[0]), bool(ms.done[0])
        w.step(ms)
        track.append(w.pos[0].copy())
        assert np.linalg.norm(w.vel[0]) <= 3.0 + 1e-9
        if ms.wp_index[0] != before or (ms.done[0] and not was_done):
            visits.append(before)  # waypoint `before` was reached on this step
            assert np.linalg.norm(w.pos[0] - wps[before]) <= arrival + 1e-9
    return ms, w, visits, np.array(track), wps


def test_path_visits_in_order_and_stops():
    ms, w, visits, track, wps = run_path(loop=False, steps=200)
    assert visits == [0, 1, 2, 3]
    assert ms.done[0] and ms.wp_index[0] == 3
    np.testing.assert_allclose(w.pos[0], wps[3], atol=1e-12)
    np.testing.assert_array_equal(w.vel[0], 0.0)
    # Straight edges at 0.3 m per step, no overshoot: each 10 m edge takes 34 steps.
    assert np.allclose(track[135:], wps[3]) and not np.allclose(track[134], wps[3])
    np.testing.assert_allclose(track[33], wps[0], atol=1e-12)
    np.testing.assert_allclose(track[16], [5.1, 0.0, 5.0], atol=1e-12)


def test_path_loops_with_arrival_radius():
    ms, w, visits, _, _ = run_path(loop=True, steps=400, arrival=0.5)
    assert visits[:9] == [0, 1, 2, 3, 0, 1, 2, 3, 0] and not ms.done[0]


def test_velocity_command_limits_and_convergence():
    n = 4
    w = World.make(n, max_speed=6.0, max_accel=2.0)
    w.vel[1] = [0.0, -5.0, 0.0]
    ms = MotionState.create(n)
    target = np.array([[3.0, 4.0, 0.0], [0, 5, 0], [20, 0, 0], [0, 0, -1]])
    set_velocity(ms, np.arange(n), target)
    clipped = target.copy()
    clipped[2] = [6.0, 0, 0]
    for _ in range(200):
        v_prev = w.vel.copy()
        w.step(ms)
        assert (np.linalg.norm(w.vel - v_prev, axis=1) <= 2.0 * DT + 1e-12).all()
        assert (np.linalg.norm(w.vel, axis=1) <= 6.0 + 1e-9).all()
    np.testing.assert_allclose(w.vel, clipped, atol=1e-12)
    np.testing.assert_allclose(w.heading[:3], np.arctan2(clipped[:3, 1], clipped[:3, 0]))
    assert w.heading[3] == 0.0  # purely vertical motion keeps the heading


def test_hold_and_offline_slots_do_not_move():
    rng = np.random.default_rng(3)
    n = 6
    w = World.make(n, pos=rng.uniform(1, 20, (n, 3)))
    w.vel[:] = 1.0
    ms = MotionState.create(n)
    set_velocity(ms, [0, 1], [5.0, 0, 0])
    set_circular(ms, [2], w.pos, [0.0, 0.0], 3.0, 1.0, 10.0)
    set_parabolic(ms, [3], w.pos, [1.0, 1.0, 1.0])
    set_hold(ms, [4, 5])
    w.online[[1, 2, 3, 5]] = False
    start = w.pos.copy()
    for fn in (integrate, integrate_reference):
        for _ in range(20):
            w.step(ms, fn)
        off = ~w.online
        np.testing.assert_array_equal(w.pos[off], start[off])
        np.testing.assert_array_equal(w.vel[off], 0.0)
        np.testing.assert_array_equal(ms.t[off], 0.0)
        np.testing.assert_array_equal(w.pos[4], start[4])
        np.testing.assert_array_equal(w.vel[4], 0.0)
        assert w.pos[0, 0] > start[0, 0]


# ---------------------------------------------------------------- kernel vs reference


def random_setup(rng: np.random.Generator, n: int) -> tuple[MotionState, World]:
    w = World.make(n, pos=rng.uniform([-50, -50, 0], [50, 50, 40], (n, 3)))
    w.max_speed[:] = rng.uniform(0.5, 12.0, n)
    w.max_accel[:] = rng.uniform(0.5, 6.0, n)
    w.online[:] = rng.random(n) < 0.85
    ms = MotionState.create(n, max_waypoints=6)
    decode_primitive(ms, np.arange(n), rng.uniform(-1, 1, (n, PRIMITIVE_ACTION_DIM)), w.pos, LIMITS)
    paths = np.flatnonzero(rng.random(n) < 0.15)
    counts = rng.integers(1, 7, paths.size)
    set_path(
        ms,
        paths,
        rng.uniform(-30, 30, (paths.size, 6, 3)),
        counts,
        rng.uniform(0, 15, paths.size),
        rng.uniform(0, 2, paths.size),
        rng.random(paths.size) < 0.5,
    )
    assert len(np.unique(ms.kind)) == 6  # every kind is exercised
    return ms, w


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_reference(seed: int):
    rng = np.random.default_rng(seed)
    n = 300
    ms_a, w_a = random_setup(rng, n)
    ms_b, w_b = ms_a.copy(), w_a.copy()
    for step in range(200):
        if step % 50 == 25:  # re-decode mid-run (keep, re-target, new primitives)
            act = rng.uniform(-1, 1, (n, PRIMITIVE_ACTION_DIM))
            decode_primitive(ms_a, np.arange(n), act, w_a.pos, LIMITS)
            decode_primitive(ms_b, np.arange(n), act, w_b.pos, LIMITS)
        w_a.step(ms_a, integrate)
        w_b.step(ms_b, integrate_reference)
        np.testing.assert_allclose(w_a.pos, w_b.pos, atol=1e-9, rtol=0)
        np.testing.assert_allclose(w_a.vel, w_b.vel, atol=1e-9, rtol=0)
        np.testing.assert_allclose(wrap(w_a.heading - w_b.heading), 0.0, atol=1e-9)
        np.testing.assert_array_equal(ms_a.done, ms_b.done)
        np.testing.assert_array_equal(ms_a.wp_index, ms_b.wp_index)
        np.testing.assert_allclose(ms_a.t, ms_b.t, atol=1e-12)


# ---------------------------------------------------------------- decoders


def test_selector_bins_and_keep_continues_circle():
    for c in range(6):
        ms = MotionState.create(1)
        sel = decode_primitive(ms, [0], np.r_[selector_action(c), np.zeros(7)][None], np.zeros((1, 3)), LIMITS)
        assert sel[0] == c
    expect = [SEL_KEEP, SEL_VELOCITY, SEL_LINEAR, SEL_CIRCULAR, SEL_PARABOLIC, SEL_GOTO]
    kinds = [HOLD, VELOCITY, LINEAR, CIRCULAR, PARABOLIC, PATH]
    ms = MotionState.create(6)
    act = np.zeros((6, PRIMITIVE_ACTION_DIM))
    act[:, 0] = [-1.0, -0.5, -0.2, 0.1, 0.5, 1.0]
    np.testing.assert_array_equal(decode_primitive(ms, np.arange(6), act, np.zeros((6, 3)), LIMITS), expect)
    np.testing.assert_array_equal(ms.kind, kinds)
    # keep: a running circle is left untouched and continues its closed form
    w = World.make(1, pos=[[5.0, 0.0, 10.0]])
    ms = MotionState.create(1)
    set_circular(ms, [0], w.pos, [0.0, 0.0], 5.0, 0.5, 10.0)
    for _ in range(30):
        before = ms.params.copy()
        decode_primitive(ms, [0], np.r_[-1.0, np.ones(7)][None], w.pos, LIMITS)
        np.testing.assert_array_equal(ms.params, before)
        w.step(ms)
    np.testing.assert_allclose(w.pos[0], [5 * np.cos(1.5), 5 * np.sin(1.5), 10.0], atol=1e-9)


def test_decoded_parameters():
    pos = np.array([[1.0, 2.0, 3.0]] * 4)
    ms = MotionState.create(4)
    act = np.zeros((4, PRIMITIVE_ACTION_DIM))
    act[:, 0] = [selector_action(c) for c in (SEL_LINEAR, SEL_CIRCULAR, SEL_GOTO, SEL_PARABOLIC)]
    act[:, 1:8] = [0.5, -0.5, 0.0, 1.0, 0.0, -1.0, 0.0]
    decode_primitive(ms, np.arange(4), act, pos, LIMITS)
    np.testing.assert_allclose(ms.params[0, 3:7], [8 / np.sqrt(2), -8 / np.sqrt(2), 0, 2.5])  # dir, u*S, u*T
    np.testing.assert_allclose(ms.params[1, :5], [1 + 15, 2 - 15, 15, 0.0, 5.0])  # centre, u*R, a*W, z_min
    np.testing.assert_allclose(ms.waypoints[2, 0], [16.0, -13.0, 5.0])
    assert ms.n_waypoints[2] == 1 and ms.params[2, 0] == 8.0 and not ms.loop[2]
    np.testing.assert_allclose(ms.params[3, 3:7], [4.0, -4.0, 0.0, 9.81])
    vel_act = np.r_[selector_action(SEL_VELOCITY), 1.0, 1.0, 1.0, np.zeros(4)][None]
    decode_primitive(ms, [3], vel_act, pos, LIMITS)  # norm clipped to S = 8
    np.testing.assert_allclose(ms.params[3, :3], np.full(3, 8 / np.sqrt(3)))
    decode_velocity(ms, [0, 1], [[1.0, 1.0, 0.0], [0.5, 0.0, -0.5]], np.array([2.0, 4.0]))
    np.testing.assert_allclose(ms.params[:2, :3], [[np.sqrt(2), np.sqrt(2), 0], [2, 0, -2]])
    assert (ms.kind[:2] == VELOCITY).all()


def test_goto_reaches_waypoint_and_hovers():
    w = World.make(1, pos=[[0.0, 0.0, 5.0]], max_speed=8.0)
    ms = MotionState.create(1)
    a = np.array([[selector_action(SEL_GOTO), 0.4, -0.2, 0.0, 1.0, 0.0, 1.0, 0.0]])
    decode_primitive(ms, [0], a, w.pos, LIMITS)
    for _ in range(60):
        w.step(ms)
    np.testing.assert_allclose(w.pos[0], [12.0, -6.0, 40.0], atol=1e-12)
    assert ms.done[0] and not w.vel.any()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_decoders_reject_non_finite(bad: float):
    ms = MotionState.create(2)
    a = np.zeros((2, PRIMITIVE_ACTION_DIM))
    a[1, 3] = bad
    with pytest.raises(ValueError, match="actions"):
        decode_primitive(ms, [0, 1], a, np.zeros((2, 3)), LIMITS)
    v = np.zeros((2, VELOCITY_ACTION_DIM))
    v[0, 2] = bad
    with pytest.raises(ValueError, match="actions"):
        decode_velocity(ms, [0, 1], v, 1.0)


def test_decoders_and_setters_reject_bad_shapes():
    ms = MotionState.create(3)
    pos = np.zeros((3, 3))
    with pytest.raises(ValueError, match="actions"):
        decode_primitive(ms, [0, 1], np.zeros((2, PRIMITIVE_ACTION_DIM - 1)), pos, LIMITS)
    with pytest.raises(ValueError, match="actions"):
        decode_velocity(ms, [0, 1], np.zeros((3, 3)), 1.0)
    with pytest.raises(ValueError, match="actions"):
        decode_velocity(ms, [0], [["a", "b", "c"]], 1.0)
    with pytest.raises(ValueError, match="pos"):
        decode_primitive(ms, [0], np.zeros((1, PRIMITIVE_ACTION_DIM)), np.zeros((2, 3)), LIMITS)
    with pytest.raises(ValueError, match="slots"):
        set_hold(ms, [3])
    with pytest.raises(ValueError, match="slots"):
        set_hold(ms, [0.5])
    with pytest.raises(ValueError, match="target_vel"):
        set_velocity(ms, [0, 1], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="speed"):
        set_linear(ms, [0], pos, [1.0, 0, 0], -1.0, 1.0)
    with pytest.raises(ValueError, match="radius"):
        set_circular(ms, [0], pos, [0.0, 0.0], np.nan, 1.0, 1.0)
    with pytest.raises(ValueError, match="gravity"):
        set_parabolic(ms, [0], pos, [0.0, 0, 1], gravity=-9.81)
    with pytest.raises(ValueError, match="waypoints"):
        set_path(ms, [0], np.zeros((1, 17, 3)))
    with pytest.raises(ValueError, match="counts"):
        set_path(ms, [0], np.zeros((1, 2, 3)), counts=[3])
    with pytest.raises(ValueError, match="waypoints"):
        set_path(ms, [0], np.full((1, 2, 3), np.nan))
    with pytest.raises(ValueError, match="dt"):
        integrate(ms, pos, np.zeros((3, 3)), np.zeros(3), np.ones(3), np.ones(3), np.ones(3, bool), 0.0)
    with pytest.raises(ValueError, match="online"):
        integrate(ms, pos, np.zeros((3, 3)), np.zeros(3), np.ones(3), np.ones(3), np.ones(2, bool), 0.1)
    with pytest.raises(ValueError, match="max_radius"):
        MotionLimits(8.0, 4.0, 0.0, 5.0, 0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="z_max"):
        MotionLimits(8.0, 4.0, 1.0, 5.0, 10.0, 1.0, 1.0)


def test_set_path_list_form_ignores_padding():
    ms = MotionState.create(2, max_waypoints=4)
    wps = [np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0], [0, 2, 0], [0, 3, 0]])]
    set_path(ms, [0, 1], wps, speed=[1.0, 2.0], loop=[True, False])
    np.testing.assert_array_equal(ms.n_waypoints, [1, 3])
    np.testing.assert_array_equal(ms.waypoints[1, :3], wps[1])
    assert not ms.waypoints[0, 1:].any()
    padded = np.full((1, 3, 3), np.nan)
    padded[0, 0] = [4.0, 4.0, 4.0]
    set_path(ms, [0], padded, counts=[1])  # NaN padding beyond counts is accepted and zeroed
    assert np.isfinite(ms.waypoints).all()


# ---------------------------------------------------------------- properties

unit = st.floats(-1.0, 1.0, allow_nan=False, width=32)


@settings(max_examples=40, deadline=None)
@given(
    act=arrays(np.float32, (5, PRIMITIVE_ACTION_DIM), elements=unit),
    choice=st.sampled_from([SEL_VELOCITY, SEL_GOTO]),
    vmax=arrays(np.float64, 5, elements=st.floats(0.1, 20.0)),
)
def test_property_speed_bounded_velocity_goto(act, choice, vmax):
    w = World.make(5, pos=np.full((5, 3), 10.0))
    w.max_speed[:] = vmax
    ms = MotionState.create(5)
    a = act.astype(np.float64)
    a[:, 0] = selector_action(choice)
    decode_primitive(ms, np.arange(5), a, w.pos, LIMITS)
    for _ in range(40):
        w.step(ms)
        assert (np.linalg.norm(w.vel, axis=1) <= vmax * (1 + 1e-12)).all()


@settings(max_examples=40, deadline=None)
@given(
    act=arrays(np.float32, (4, VELOCITY_ACTION_DIM), elements=unit),
    vmax=st.floats(0.0, 30.0),
    wmax=st.floats(0.1, 30.0),
    seed=st.integers(0, 2**16),
)
def test_property_speed_bounded_velocity_and_path(act, vmax, wmax, seed):
    rng = np.random.default_rng(seed)
    w = World.make(8, pos=rng.uniform(-10, 10, (8, 3)), max_speed=wmax)
    w.vel[:4] = rng.uniform(-1, 1, (4, 3)) * wmax / 2
    ms = MotionState.create(8)
    decode_velocity(ms, np.arange(4), act, vmax)
    set_path(ms, np.arange(4, 8), rng.uniform(-20, 20, (4, 3, 3)), speed=rng.uniform(0, 40, 4), loop=True)
    for _ in range(30):
        w.step(ms)
        assert (np.linalg.norm(w.vel, axis=1) <= wmax * (1 + 1e-12)).all()


@settings(max_examples=40, deadline=None)
@given(act=arrays(np.float32, (3, PRIMITIVE_ACTION_DIM), elements=unit), seed=st.integers(0, 2**16))
def test_property_circle_radius_conserved(act, seed):
    rng = np.random.default_rng(seed)
    w = World.make(3, pos=rng.uniform(-20, 20, (3, 3)), max_speed=6.0)
    ms = MotionState.create(3)
    a = act.astype(np.float64)
    a[:, 0] = selector_action(SEL_CIRCULAR)
    decode_primitive(ms, np.arange(3), a, w.pos, LIMITS)
    centre, radius = ms.params[:, 0:2].copy(), ms.params[:, 2].copy()
    for _ in range(50):
        w.step(ms)
        np.testing.assert_allclose(np.linalg.norm(w.pos[:, :2] - centre, axis=1), radius, atol=1e-9)
        assert (np.linalg.norm(w.vel, axis=1) <= 6.0 * (1 + 1e-12)).all()


@settings(max_examples=60, deadline=None)
@given(act=arrays(np.float32, (6, PRIMITIVE_ACTION_DIM), elements=unit), seed=st.integers(0, 2**16))
def test_property_any_action_decodes_to_finite_state(act, seed):
    rng = np.random.default_rng(seed)
    w = World.make(6, pos=rng.uniform(-5, 5, (6, 3)))
    ms = MotionState.create(6)
    for _ in range(3):
        decode_primitive(ms, np.arange(6), act, w.pos, LIMITS)
        for _ in range(10):
            w.step(ms)
    for arr in (ms.params, ms.t, ms.waypoints, w.pos, w.vel, w.heading):
        assert np.isfinite(arr).all()
