"""The JSON WebSocket's `?sysid=` and `?compid=` filters beside `filter=` (mavlink2rest #119,
mavp2p #184) and `/mavlink2rest/ws/mavlink`, BlueOS's proxy path, as an alias of
`/v1/ws/mavlink` (SPEC.md "Web tools and monitoring")."""

from __future__ import annotations

import asyncio
import json

import aiohttp

from .helpers import VEHICLE, is_type, udp_channel, udp_url, wait_for
from .http_client import call


async def _collect(url: str, seconds: float, until: int | None = None) -> list[dict]:
    """Text frames of one WebSocket for `seconds` (or until `until` frames came)."""
    frames: list[dict] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
        end = asyncio.get_running_loop().time() + seconds
        while until is None or len(frames) < until:
            left = end - asyncio.get_running_loop().time()
            if left <= 0:
                break
            try:
                msg = await ws.receive(timeout=left)
            except TimeoutError:
                break
            if msg.type == aiohttp.WSMsgType.TEXT:
                frames.append(json.loads(msg.data))
    return frames


async def _both(*coros):
    return await asyncio.gather(*coros)


def test_sysid_and_compid_filters_and_the_blueos_alias(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE))
    ws = d.http_url().replace("http://", "ws://")
    hb = "/v1/ws/mavlink?filter=^HEARTBEAT$"
    # in one window: sysid=1 gets the vehicle's heartbeats; sysid=2 and compid=9 get nothing
    ours, other_system, other_component, alias = asyncio.run(_both(
        _collect(f"{ws}{hb}&sysid=1&compid=1", 2.5, until=2),
        _collect(f"{ws}{hb}&sysid=2", 2.5),
        _collect(f"{ws}{hb}&compid=9", 2.5),
        _collect(f"{ws}/mavlink2rest/ws/mavlink?filter=^HEARTBEAT$", 2.5, until=2)))
    assert len(ours) == 2 and {(f["header"]["system_id"], f["header"]["component_id"]) for f in ours} == {VEHICLE}
    assert other_system == [] and other_component == []
    assert len(alias) == 2 and alias[0]["message"]["type"] == "HEARTBEAT"
    # a bad id is a 400 before the upgrade, as a bad filter
    for query in ("sysid=x", "sysid=256", "compid=-1", "sysid=%C2%B2"):
        status = call(f"{d.http_url()}/v1/ws/mavlink?{query}",
                      headers={"Connection": "Upgrade", "Upgrade": "websocket", "Sec-WebSocket-Version": "13",
                               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})[0]
        assert status == 400, query
