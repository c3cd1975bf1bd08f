"""The loop's error log says a repeated error once per window, with a count."""

from __future__ import annotations

import asyncio
import errno

from structlog.testing import capture_logs

from fcmaster.process_limits import RepeatedErrors


async def test_an_error_that_repeats_is_logged_once_then_counted() -> None:
    loop = asyncio.get_running_loop()
    handler = RepeatedErrors(loop, window_s=0.05)
    emfile = OSError(errno.EMFILE, "Too many open files")
    with capture_logs() as logs:
        for _ in range(1000):
            handler(
                loop, {"message": "socket.accept() out of system resource", "exception": emfile}
            )
        handler(loop, {"message": "another thing went wrong"})
        await asyncio.sleep(0.2)
        handler(loop, {"message": "socket.accept() out of system resource", "exception": emfile})
    lines = [(e["event"], e["message"], e.get("count")) for e in logs]
    assert lines == [
        ("loop.error", "socket.accept() out of system resource", None),
        ("loop.error", "another thing went wrong", None),
        ("loop.error_repeated", "socket.accept() out of system resource", 999),
        ("loop.error", "socket.accept() out of system resource", None),  # a new window
    ]
