"""A minimal viser 1.1 client over a real websocket, for server tests without a browser.

It speaks what viser's page speaks: the ``viser-v<version>`` subprotocol,
msgpack messages ``{"type": <message class name>, **fields}`` to the server,
and zstd-compressed msgpack windows from it (layout in viser's
``infra/_infra.py::_message_producer``).
"""

from __future__ import annotations

import asyncio
import time
import uuid
from typing import Any, Callable

import msgspec
import viser
import websockets.asyncio.client as ws_client
import zstandard

SUBPROTOCOL = f"viser-v{viser.__version__}"


def decode_window(raw: bytes) -> list[dict]:
    """The messages of one server -> client window."""
    n_inner = int.from_bytes(raw[:8], "little")
    n_comp = int.from_bytes(raw[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[16:16 + n_comp], max_output_size=n_inner)
    return list(msgspec.msgpack.decode(inner)["messages"])


class WireClient:
    """One tab: ``async with WireClient(port) as tab: ...``."""

    def __init__(self, port: int, origin: str | None = None) -> None:
        self.port = port
        self.origin = origin if origin is not None else f"http://127.0.0.1:{port}"
        self.messages: list[dict] = []
        self._ws: Any = None
        self._task: asyncio.Task | None = None

    async def __aenter__(self) -> "WireClient":
        self._ws = await ws_client.connect(f"ws://127.0.0.1:{self.port}", origin=self.origin,
                                           subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=20)
        self._task = asyncio.create_task(self._receive())
        # viser counts a tab as connected (and runs on_client_connect) after its first camera message.
        await self.send("ViewerCameraMessage", wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 0.0, -10.0), fov=0.5,
                        near=0.01, far=1000.0, image_height=720, image_width=1280, look_at=(0.0, 0.0, 0.0),
                        up_direction=(0.0, -1.0, 0.0))
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self._ws.close()
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except (asyncio.CancelledError, Exception):
                pass

    async def _receive(self) -> None:
        async for raw in self._ws:
            self.messages.extend(decode_window(raw))

    async def wait_for(self, predicate: Callable[[dict], bool], timeout: float = 20.0) -> dict:
        """The first message (received so far or later) that satisfies ``predicate``."""
        deadline = time.monotonic() + timeout
        seen = 0
        while True:
            for m in self.messages[seen:]:
                if predicate(m):
                    return m
            seen = len(self.messages)
            if time.monotonic() > deadline:
                raise TimeoutError("no such message from the server")
            await asyncio.sleep(0.02)

    async def send(self, type_name: str, **fields: Any) -> None:
        await self._ws.send(msgspec.msgpack.encode({"type": type_name, **fields}))

    async def gui_uuid(self, type_name: str, label: str) -> str:
        """uuid of the GUI element of this type and label that the server created for this tab."""
        m = await self.wait_for(lambda m: m.get("type") == type_name and m.get("props", {}).get("label") == label)
        return m["uuid"]

    async def press_new_buttons(self, label: str) -> int:
        """Press every button labelled ``label`` the server made for this tab and not yet pressed; how many."""
        pressed = self.__dict__.setdefault("_pressed", set())
        found = [m["uuid"] for m in list(self.messages)
                 if m.get("type") == "GuiButtonMessage" and m.get("props", {}).get("label") == label
                 and m["uuid"] not in pressed]
        for button in found:
            pressed.add(button)
            await self.send("GuiUpdateMessage", uuid=button, updates={"value": True})
        return len(found)

    async def upload(self, button_uuid: str, filename: str, content: bytes) -> None:
        """Upload a file through an upload button, in one part."""
        transfer = str(uuid.uuid4())
        await self.send("FileTransferStartUpload", source_component_uuid=button_uuid, transfer_uuid=transfer,
                        filename=filename, mime_type="application/x-yaml", part_count=1, size_bytes=len(content))
        await self.send("FileTransferPart", source_component_uuid=button_uuid, transfer_uuid=transfer, part_index=0,
                        content=content)

    async def click(self, node: str, ray_origin, ray_direction, modifier: str | None = None) -> None:
        """Click scene node ``node`` along a ray (world frame)."""
        await self.send("SceneNodeClickMessage", name=node, instance_index=None,
                        ray_origin=tuple(float(x) for x in ray_origin),
                        ray_direction=tuple(float(x) for x in ray_direction), screen_pos=(0.5, 0.5),
                        modifier=modifier, owner="")
