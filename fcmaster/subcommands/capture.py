"""`fcmaster capture`: a running line's frames, with their times, into a pcapng file.

It follows the daemon's frame log (``GET /api/v1/buses/NAME/frames?since=SEQ``) for the
given seconds, from the moment it starts, and writes each frame as it comes: requests the
master wrote as outbound packets, what it read as inbound ones (see
:mod:`fcmaster.protocol.pcapng` for the link types). The file is written as it goes, so a
capture cut short still holds what came before.

Timestamps come from the daemon's monotonic clock, anchored once to its wall clock: they
always increase and keep the true spacing of the frames, even if the wall clock is
stepped during the capture. The daemon keeps the last few thousand frames of each line
and the capture asks every quarter second, so it falls behind only if a request stalls for
tens of seconds; frames it missed are counted, and the next packet says so in a comment.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any, BinaryIO, Final, TextIO
from urllib.parse import quote

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.errors import FcmasterError, UsageError
from fcmaster.protocol import pcapng
from fcmaster.protocol.pcapng import Interface, LineFormat, Packet
from fcmaster.subcommands.urls import daemon_url

POLL_S: Final = 0.25
REQUEST_TIMEOUT_S: Final = 10.0


def frames_url(url: str, bus: str) -> str:
    """``http://host:8080`` → ``http://host:8080/api/v1/buses/BUS/frames``."""
    parts = daemon_url(url, ("http", "https"))
    base = f"{parts.scheme}://{parts.netloc}{parts.path.rstrip('/')}"
    return f"{base}/api/v1/buses/{quote(bus, safe='')}/frames"


class _Follower:
    """Asks the daemon for a line's frames after the last ones it got."""

    def __init__(self, url: str, bus: str, token: str | None) -> None:
        self.url, self.bus = url, bus
        self.endpoint = frames_url(url, bus)
        self.headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.has_token = bool(token)

    def get(self, since: int) -> dict[str, Any]:
        request = urllib.request.Request(f"{self.endpoint}?since={since}", headers=self.headers)
        try:
            with urllib.request.urlopen(request, timeout=REQUEST_TIMEOUT_S) as response:
                body: dict[str, Any] = json.load(response)
                return body
        except urllib.error.HTTPError as exc:
            raise self._refusal(exc.code) from exc
        except (urllib.error.URLError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            raise FcmasterError(f"cannot reach {self.url}: {reason}") from exc
        except ValueError as exc:
            raise FcmasterError(f"{self.url} did not answer with JSON: is it fcmaster?") from exc

    def _refusal(self, status: int) -> FcmasterError:
        if status == 404:
            return UsageError(f"{self.url} has no bus called {self.bus!r} (HTTP 404)")
        if status in (401, 403) and self.has_token:
            return UsageError(f"{self.url} does not accept this token (HTTP {status})")
        if status in (401, 403):
            return UsageError(f"{self.url} wants a viewer token (HTTP {status}): pass --token")
        return FcmasterError(f"{self.url} answered HTTP {status}")


def line_interface(body: dict[str, Any], url: str) -> Interface:
    """The pcapng interface of the line a frames response describes."""
    protocol = body["protocol"]
    link_type = pcapng.LINK_TYPES.get(protocol)
    if link_type is None:
        raise FcmasterError(f"no link type for protocol {protocol!r}")
    description = LineFormat(
        protocol, body["baudrate"], body["databits"], body["parity"], body["stopbits"]
    )
    return Interface(
        link_type=link_type,
        name=body["bus"],
        description=str(description),
        speed=body["baudrate"],
        comment=f"{protocol} frames of bus {body['bus']} from {url}",
    )


async def capture(
    url: str,
    bus: str,
    seconds: float,
    output: Path,
    token: str | None = None,
    *,
    out: TextIO | None = None,
    clock: Clock | None = None,
    poll_s: float = POLL_S,
) -> int:
    """Follow bus ``bus`` of the daemon at ``url`` for ``seconds`` into ``output``."""
    if not seconds > 0:
        raise UsageError(f"--seconds must be more than 0, not {seconds}")
    out = out or sys.stdout
    clock = clock or MonotonicClock()
    follower = _Follower(url, bus, token or os.environ.get("FCM_TOKEN"))
    first = await asyncio.to_thread(
        follower.get, 0
    )  # what is in the ring already came before the capture
    interface = line_interface(first, url)
    since = first["next"]
    end = clock.now() + seconds
    counts = {"tx": 0, "rx": 0}
    missed_total = 0
    anchor_us: int | None = None  # the daemon's wall minus monotonic time, at the first frame
    try:
        file = await asyncio.to_thread(output.open, "wb")
        with file:
            file.write(pcapng.section_header("fcmaster capture"))
            file.write(pcapng.interface_description(interface))
            while True:
                body = await asyncio.to_thread(follower.get, since)
                missed = body["missed"]
                missed_total += missed
                for frame in body["frames"]:
                    if anchor_us is None:
                        anchor_us = round(frame["time"] * 1e6) - round(frame["mono"] * 1e6)
                    _write(file, frame, anchor_us, missed, interface.link_type)
                    counts[frame["dir"]] = counts.get(frame["dir"], 0) + 1
                    missed = 0
                file.flush()
                since = body["next"]
                if clock.now() >= end:
                    break
                await clock.sleep(min(poll_s, max(0.0, end - clock.now())))
    finally:  # also when cut short (Ctrl-C): the file holds the frames so far
        total = counts["tx"] + counts["rx"]
        lost = f"; {missed_total} frames missed" if missed_total else ""
        print(
            f"{total} frames ({counts['tx']} sent, {counts['rx']} received) "
            f"of bus {bus} in {output}{lost}",
            file=out,
        )
    return 0


def _write(
    file: BinaryIO, frame: dict[str, Any], anchor_us: int, missed: int, link_type: int
) -> None:
    direction = pcapng.OUTBOUND if frame["dir"] == "tx" else pcapng.INBOUND
    comment = f"{missed} frames missed before this one" if missed else ""
    packet = Packet(
        interface=0,
        # in whole microseconds before adding: a sum near 1.8e9 s in floating point would
        # jitter by a microsecond and lose the frames' exact spacing
        timestamp_us=round(frame["mono"] * 1e6) + anchor_us,
        data=bytes.fromhex(frame["data"]),
        direction=direction,
        comment=comment,
    )
    file.write(pcapng.enhanced_packet(packet, link_type))
