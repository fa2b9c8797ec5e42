"""The live viewer: a stage-10 step hook that streams one world to the web page, and the page's controls.

``WebViewer.attach(world, scenario)`` starts the server (``server.WebServer``) and adds the hook. Each step the hook
(in the simulation's thread) appends the step's log lines when a page is connected, packs a frame only when a
page can take one (``WebServer.wants_frame``: latest state wins, a slow page never blocks the step), and then
honours the page's controls: while paused it waits (a *step* lets one step through), and with a speed set it paces
the simulation to that many steps per second. ``render_mode="web"`` and ``agentsim view`` both use it.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from agentsim_env.render.web.frames import (
    agent_message,
    log_lines,
    new_status,
    pack_frame,
    scene_message,
    state_arrays,
    track_status,
)
from agentsim_env.render.web.server import TICK_S, ClientError, WebServer
from agentsim_env.sim.world import StepEvents, World

STATUS_EVERY = 0.5  # seconds between status / selected-agent updates
MIN_SPEED = 0.1  # slowest pace in steps per second (one step every 10 s); 0 means as fast as possible
MAX_SPEED = 10000.0
PACE_SLICE_S = 0.05  # pace() never sleeps longer than this without looking at the controls again
SPEED_RANGE = f"0 (as fast as possible) or a number of steps per second in {MIN_SPEED:g}..{MAX_SPEED:g}"


def speed_ok(value: object) -> bool:
    """Whether ``value`` is a speed the controls take: 0, or a number in ``MIN_SPEED..MAX_SPEED``.

    Args:
        value: Anything (a page's JSON value, a command-line number).

    Returns:
        True for 0 and for an int or float (not a bool) in the range; False otherwise, NaN included.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return value == 0 or MIN_SPEED <= value <= MAX_SPEED


def _shown(value: object) -> str:
    """A short form of a page's value for an error message (never the whole of a long string or list)."""
    if isinstance(value, str):
        return repr(value[:40]) + ("..." if len(value) > 40 else "")
    if isinstance(value, (list, dict)):
        return f"a JSON {'array' if isinstance(value, list) else 'object'}"
    return repr(value)[:40]


def clamp_speed(rate: float) -> float:
    """A derived rate (such as real time, ``1 / dt``) brought into ``MIN_SPEED..MAX_SPEED`` (0 if not finite)."""
    if not rate == rate or rate <= 0:  # NaN or not positive: as fast as possible
        return 0.0
    return min(max(float(rate), MIN_SPEED), MAX_SPEED)


class Controls:
    """Pause, single steps, speed and the selected agent, set by the page (server thread), read by the driver.

    Args:
        speed: Steps per second: 0 (as fast as possible) or ``MIN_SPEED..MAX_SPEED``.

    Raises:
        ValueError: If ``speed`` is outside that range.
    """

    def __init__(self, speed: float = 0.0) -> None:
        if not speed_ok(speed):
            raise ValueError(f"speed must be {SPEED_RANGE}, got {speed!r}")
        self.paused = False
        self.speed = float(speed)
        self.selected: int | None = None
        self.n_agents = 0
        self.closed = False
        self._tokens = 0
        self._cond = threading.Condition()
        self._next = 0.0
        #: The full status message the replies to pause / resume / step / speed carry (the viewer's: with the
        #: step and the steps/s a page shows); by default the controls' own fields only.
        self.reply: Callable[[], dict[str, Any]] = self.status

    def handlers(self, extra: dict[str, Any] | None = None) -> dict[str, Any]:
        """The server's command handlers for pause, resume, step, speed and select."""
        return {
            "pause": self._pause,
            "resume": self._resume,
            "step": self._step,
            "speed": self._speed,
            "select": self._select,
            **(extra or {}),
        }

    @staticmethod
    def _only(msg: dict[str, Any], keys: tuple[str, ...]) -> None:
        extra = sorted(set(msg) - {"cmd", *keys})
        if extra:
            raise ClientError(f"{msg['cmd']}: unknown field(s) {extra}; allowed: {list(keys)}")

    def _pause(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._only(msg, ())
        with self._cond:
            self.paused = True
            self._cond.notify_all()  # a pacing driver stops waiting and holds in gate() instead
        return self.reply()

    def _resume(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._only(msg, ())
        with self._cond:
            self.paused = False
            self._next = 0.0
            self._cond.notify_all()
        return self.reply()

    def _step(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._only(msg, ())
        with self._cond:
            self.paused = True
            self._tokens += 1
            self._cond.notify_all()
        return self.reply()

    def _speed(self, msg: dict[str, Any]) -> dict[str, Any]:
        self._only(msg, ("value",))
        v = msg.get("value")
        if not speed_ok(v) or not isinstance(v, (int, float)):  # (the second test: for the type checker)
            raise ClientError(f"speed: 'value' must be {SPEED_RANGE}, got {_shown(v)}")
        with self._cond:
            self.speed = float(v)
            self._next = 0.0
            self._cond.notify_all()  # a driver pacing at the old speed takes the new one at once
        return self.reply()

    def _select(self, msg: dict[str, Any]) -> dict[str, Any] | None:
        self._only(msg, ("slot",))
        slot = msg.get("slot")
        if slot is not None and (isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < self.n_agents):
            raise ClientError(f"select: 'slot' must be an agent index in 0..{self.n_agents - 1} or null, got {slot!r}")
        self.selected = slot
        return None

    def status(self) -> dict[str, Any]:
        """A ``status`` message with the controls' state (the driver adds step numbers)."""
        return {"type": "status", "paused": self.paused, "speed": self.speed}

    def wait_turn(self, timeout: float) -> bool:
        """Whether the driver may take a step now (running, or a step token, which this takes); while paused
        it waits up to ``timeout`` seconds for one. False when closed."""
        with self._cond:
            if self.paused and not self._tokens and not self.closed:
                self._cond.wait(timeout)
            if self.closed:
                return False
            if self._tokens:
                self._tokens -= 1
                return True
            return not self.paused

    def gate(self) -> None:
        """Wait while paused (a step token lets one step through); returns at once when closed."""
        while not self.closed and not self.wait_turn(0.25):
            pass

    def pace(self) -> None:
        """Wait so that steps follow at ``speed`` per second (no-op at speed 0 or when behind).

        The wait is cut short by any change of the controls (a new speed, pause, step, resume, close), so a
        slow speed never parks the driver: it looks at the controls at least every ``PACE_SLICE_S``.
        """
        with self._cond:
            speed = self.speed
            if not MIN_SPEED <= speed <= MAX_SPEED:  # 0: as fast as possible (and nothing else gets here)
                return
            now = time.perf_counter()
            if self._next <= 0.0 or now - self._next > 1.0:  # first step, or far behind: restart the clock
                self._next = now
            self._next += 1.0 / speed
            due = self._next
            while not self.closed and not self.paused and not self._tokens and self.speed == speed:
                left = due - time.perf_counter()
                if left <= 0.0 or self._next != due:  # due, or the clock was restarted (resume, new speed)
                    return
                self._cond.wait(min(left, PACE_SLICE_S))

    def close(self) -> None:
        """Release a waiting driver for good."""
        with self._cond:
            self.closed = True
            self._cond.notify_all()


class WebViewer:
    """Streams world ``w`` of a simulation to a browser page (the step hook of ``render_mode="web"``).

    Args:
        host: Address to bind (127.0.0.1: this machine only; anything else prints a warning).
        port: Port (0: a free one).
        speed: Initial steps per second: 0 (as fast as the simulation runs) or ``MIN_SPEED..MAX_SPEED``.
        title: Page title (default: the scenario's name).
        w: Which world of a batched world to show.
        quiet: Print nothing (otherwise the URL is printed when the server starts).
        max_fps: Most frames a second sent to a page.
        wait: Hold the first episode until a page is connected (``agentsim view`` does; ``--no-wait`` does not),
            so that the page shows it from step 0. ``render_mode="web"`` does not wait: call
            ``env.viewer.wait_for_page()`` after the first ``reset`` to hold there.
    """

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        speed: float = 0.0,
        title: str = "",
        w: int = 0,
        quiet: bool = False,
        max_fps: float = 60.0,
        wait: bool = False,
    ) -> None:
        self.controls = Controls(speed)
        self.controls.reply = self._status
        handlers = self.controls.handlers({"select": self._select})
        self.server = WebServer(
            "viewer.html",
            host=host,
            port=port,
            title=title or "agentsim viewer",
            handlers=handlers,
            on_connect=self._hello,
            max_fps=max_fps,
            on_tick=self._flush,
        )
        self.title = title
        self.w = w
        self.quiet = quiet
        self.world: World | None = None
        self.scenario: Any = None
        self.episode = -1
        self.seq = 0
        self._scene: dict[str, Any] | None = None
        self._last_status = 0.0
        self._steps_since = 0
        self._rate = 0.0
        self._events: StepEvents | None = None  # the step a paused simulation waits after
        self._held: StepEvents | None = None  # a step the frame-rate cap held back (sent if no step follows)
        self._last_hook = 0.0
        self._frame_lock = threading.Lock()
        self._names: list[str] = []
        self.wait = wait
        self._why = np.zeros(0, np.uint8)  # why each agent is (not) active (frames.STATUS_NAMES)

    @property
    def url(self) -> str:
        """The page's address ("" before ``attach``)."""
        return self.server.url

    def attach(self, world: World, scenario: Any) -> str:
        """Start the server (once) and stream ``world``; returns the URL."""
        if self.world is not None and self.world is not world:
            self.world.remove_hook(self.hook)
        self.world, self.scenario = world, scenario
        self._names = scenario.agent_names()
        self.controls.n_agents = world.n_agents
        if self.hook not in world.hooks:
            world.add_hook(self.hook)
        if not self.server.url:
            url = self.server.start()
            if not self.quiet:
                print(f"agentsim viewer: {url}", file=sys.stderr, flush=True)
                if self.server.host not in ("127.0.0.1", "localhost", "::1"):
                    print(
                        f"agentsim viewer: WARNING: serving on {self.server.host}, reachable from other machines; "
                        "the page has no authentication",
                        file=sys.stderr,
                        flush=True,
                    )
        return self.server.url

    def new_episode(self, episode: int | None = None) -> None:
        """A reset happened: send the new scene (objects may have moved) and the first frame."""
        assert self.world is not None, "attach() first"
        self.episode = self.episode + 1 if episode is None else episode
        self._scene = scene_message(self.world, self.scenario, self.w, title=self.title)
        self._reset_status()
        self.server.broadcast(self._scene)
        self.server.publish_log(
            [
                {
                    "step": 0,
                    "episode": self.episode,
                    "kind": "episode",
                    "text": f"episode {self.episode} started",
                    "slots": [],
                }
            ]
        )
        self._send_frame(None)
        if self.wait:  # the first episode only: later ones go on whether or not a page watches
            self.wait = False
            self.wait_for_page()

    def wait_for_page(self, timeout: float | None = None) -> bool:
        """Block until a page is connected (or ``close``, or ``timeout`` seconds); whether one is.

        Waits in short slices so that Ctrl-C in the calling thread is seen at once.
        """
        if not self.quiet and not self.server.n_pages and self.server.url:
            print(
                f"agentsim viewer: waiting for a page at {self.server.url} (open it to start)",
                file=sys.stderr,
                flush=True,
            )
        end = None if timeout is None else time.perf_counter() + timeout
        while not self.server.n_pages and not self.controls.closed:
            if end is not None and time.perf_counter() >= end:
                break
            time.sleep(0.05)
        return self.server.n_pages > 0

    def _reset_status(self) -> None:
        """A new episode: every agent active."""
        assert self.world is not None
        self._why = new_status(self.world.state.n_agents)

    def _track(self, events: StepEvents) -> None:
        """Record why agents stopped this step (every step, whether or not a frame is sent)."""
        if self.world is not None:
            if self._why.shape[0] != self.world.state.n_agents:
                self._reset_status()
            track_status(self._why, self.world, self.w, events)

    def _flush(self) -> None:
        """Server thread: when steps stopped after one the frame-rate cap held back, send that step's frame.

        The simulation has been idle for a while (no hook ran), so its state holds still while it is read.
        """
        held = self._held
        if held is not None and time.perf_counter() - self._last_hook > 2 * TICK_S and self.server.ready_pages:
            self._held = None
            self._send_frame(held)

    def _select(self, msg: dict[str, Any]) -> dict[str, Any] | None:
        """Select an agent: its state and inbox at once; while paused, a frame with its rays too."""
        self.controls._select(msg)
        sel, world = self.controls.selected, self.world
        if sel is None or world is None:
            return None
        if self.controls.paused:  # the simulation waits in gate(): its state holds still
            self._send_frame(self._events)
        return agent_message(world, self.scenario, self.w, sel)

    def _hello(self) -> list[dict[str, Any]]:
        out = [self._scene] if self._scene is not None else []
        return out + [self._status()]

    def _status(self) -> dict[str, Any]:
        step = int(self.world.step_count[self.w]) if self.world is not None else 0
        return {
            **self.controls.status(),
            "step": step,
            "episode": self.episode,
            "steps_per_s": round(self._rate, 1),
        }

    def _send_frame(self, events: StepEvents | None) -> None:
        world = self.world
        assert world is not None
        with self._frame_lock:  # the simulation's thread and the server's (_flush, _select) both send frames
            self.seq += 1
            arrays = state_arrays(
                world,
                self.w,
                events,
                self.controls.selected,
                self._why if self._why.shape[0] == world.state.n_agents else None,
            )
            frame = pack_frame(self.seq, int(world.step_count[self.w]), self.episode, arrays)
            self.server.publish_frame(self.seq, frame)

    def hook(self, world: World, events: StepEvents) -> None:
        """Stage 10: log lines, a frame when a page can take one, status; then pace and pause."""
        srv = self.server
        self._track(events)
        if srv.n_pages:
            srv.publish_log(log_lines(world, self.scenario, events, self.w, self.episode, self._names))
            if srv.wants_frame():
                self._send_frame(events)
                self._held = None
            elif srv.ready_pages:
                self._held = events
        self._last_hook = time.perf_counter()
        self._steps_since += 1
        now = time.perf_counter()
        if now - self._last_status >= STATUS_EVERY:
            if self._last_status > 0:
                self._rate = self._steps_since / (now - self._last_status)
            self._last_status, self._steps_since = now, 0
            if srv.n_pages:
                srv.broadcast(self._status())
                sel = self.controls.selected
                if sel is not None:
                    srv.broadcast(agent_message(world, self.scenario, self.w, sel))
        self.controls.pace()  # cut short by a pause, which then holds this very step
        if self.controls.paused:
            self._events = events
            self._send_frame(events)  # the page shows the step the simulation is paused on
            srv.broadcast(self._status())
            self.controls.gate()
            self._events = None

    def close(self) -> None:
        """Remove the hook, release a paused step and stop the server."""
        self.controls.close()
        if self.world is not None and self.hook in self.world.hooks:
            self.world.hooks = [h for h in self.world.hooks if h != self.hook]
        self.server.stop()


__all__ = ["MAX_SPEED", "MIN_SPEED", "SPEED_RANGE", "Controls", "WebViewer", "clamp_speed", "speed_ok"]
