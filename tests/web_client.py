"""A plain WebSocket client that stands in for a viewer page in the server tests."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

from websockets.asyncio.client import connect

from agentsim_env.render.web.frames import unpack_frame


def talk(url: str, send: list[Any], seconds: float = 1.0, ack_delay: float = 0.0) -> tuple[list[dict], list[bytes]]:
    """Connect to the page's socket, send ``send`` (objects as JSON, strings and bytes as they are), collect for
    ``seconds``; each frame is acknowledged ``ack_delay`` seconds after it arrived (a slow page)."""
    texts: list[dict] = []
    frames: list[bytes] = []

    async def run() -> None:
        async with connect(url.replace("http", "ws") + "ws", max_size=None) as ws:
            for m in send:
                await ws.send(m if isinstance(m, (str, bytes)) else json.dumps(m))
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    m = await asyncio.wait_for(ws.recv(), 0.1)
                except asyncio.TimeoutError:
                    continue
                if isinstance(m, bytes):
                    frames.append(m)
                    if ack_delay:
                        await asyncio.sleep(ack_delay)
                    await ws.send(json.dumps({"cmd": "ack", "seq": unpack_frame(m)[0]["seq"]}))
                else:
                    texts.append(json.loads(m))

    asyncio.run(run())
    return texts, frames
