"""The simulator on a pseudo-terminal, so a master opens it as a real serial device.

Theory of operation
-------------------
:class:`PtyServer` opens a pty pair and serves one :class:`~fcmaster.sim.line.SimLine` on
the master side; clients open the slave path (or the ``link`` pointing at it) with any
serial library. The server keeps its own slave descriptor open for its whole life, so a
client closing the device never makes the master side return EIO or hang up, and clients
can come and go.

Receiving: the event loop's reader callback hands each chunk to the line, stamped with the
clock's ``now()``. Sending: one pump task sleeps on the clock until the line's next
delivery time and writes what is due; a write that brings an earlier delivery (an echo, a
noise burst) restarts the pump. Run under :func:`fcmaster.clock.new_event_loop`, whose
timers keep sub-millisecond time, with a :class:`~fcmaster.clock.MonotonicClock`, which
wakes early by its own learned lateness and spins to the deadline, replies leave on their
wire time to within microseconds; what remains is the pty's own delay.

Parity and termios: a pty carries bytes, not characters, and Linux strips PARENB from its
termios. glibc's ``tcsetattr`` reads the termios before and after the ``TCSETS`` ioctl and
reports EINVAL when nothing changed although the request asked for PARENB — so the second
pyserial open of a pty with parity E fails, because the first left every other flag as the
second asks. The server therefore keeps the slave at a *baseline* (raw, EXTPROC set, and a
speed of 50 or 75 baud that no client asks for), so a client's configuration always changes
the speed too and is accepted. With EXTPROC set and packet mode on the master side, the
kernel reports every ``tcsetattr`` on the slave (TIOCPKT_IOCTL); the server then puts a
baseline back, ready for the next open — the *other* one of the two, so that a restore
landing between a client's ``TCSETS`` and glibc's read-back still counts as a change. A
client that reopens within the loop's reaction time (tens of microseconds) can still meet
its own settings and fail. The line's character format lives in the SimLine, not in
termios; the client's speed, read when it sets it, tells the line whether the master talks
at the line's baud rate.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import os
import struct
import sys
import termios
import tty
from types import TracebackType
from typing import Any, Final

from fcmaster.clock import Clock
from fcmaster.errors import PortError, UsageError
from fcmaster.sim.line import SimLine

_TIOCPKT: Final = getattr(termios, "TIOCPKT", 0x5420)
_TIOCPKT_DATA: Final = 0x00
_TIOCPKT_IOCTL: Final = 0x40
_EXTPROC: Final = getattr(termios, "EXTPROC", 0o200000)
_BASELINE_SPEEDS: Final = (termios.B50, termios.B75)  # no client asks for these
_LFLAG, _ISPEED, _OSPEED = 3, 4, 5  # indices into a tcgetattr list
# termios speed constants → baud rates (B9600 → 9600); an unknown speed tells nothing
_BAUD_OF_SPEED: Final = {
    getattr(termios, name): int(name[1:])
    for name in dir(termios)
    if name[:1] == "B" and name[1:].isdigit() and int(name[1:]) > 0
}
# A rate termios has no constant for (76800) is set as BOTHER with the number in termios2,
# which TCGETS2 reads: struct termios2 is 4 flag words, c_line, 19 c_cc, c_ispeed, c_ospeed.
_BOTHER: Final = getattr(termios, "BOTHER", 0o010000)
_TCGETS2: Final = 0x802C542A  # _IOR('T', 0x2A, struct termios2) on asm-generic ioctls
_TERMIOS2_SIZE, _TERMIOS2_OSPEED = 44, 40


def _baud_of(fd: int, speed: int) -> int | None:
    """The baud rate a client set on the pty ``fd`` (termios speed ``speed``), if known."""
    if speed != _BOTHER:
        return _BAUD_OF_SPEED.get(speed)
    buffer = bytearray(_TERMIOS2_SIZE)
    try:
        fcntl.ioctl(fd, _TCGETS2, buffer, True)
    except OSError:
        return None  # another ABI: an unknown speed tells nothing
    baud = int.from_bytes(buffer[_TERMIOS2_OSPEED : _TERMIOS2_OSPEED + 4], sys.byteorder)
    return baud or None


class PtyServer:
    """Serves a simulated line on a pseudo-terminal; an async context manager."""

    def __init__(self, line: SimLine, *, clock: Clock, link: str | None = None) -> None:
        """Serve ``line`` (which must read ``clock``); ``link`` gets a symlink to the device."""
        self.line = line
        self.link = link
        self._clock = clock
        self._master = self._slave = -1
        self.path = ""
        self._baselines: list[list[Any]] = []  # as tcgetattr returns them
        self._baseline = 0  # index of the one set last
        self._pump: asyncio.Task[None] | None = None
        self._idle = asyncio.Event()
        self._pump_until: float | None = None
        self.overruns = 0  # reply bytes dropped because no client was reading

    async def __aenter__(self) -> PtyServer:
        self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        await self.close()

    @property
    def device(self) -> str:
        """The path clients should open: the link if there is one, else the pty slave."""
        return self.link or self.path

    def open(self) -> None:
        """Create the pty (and link) and start serving on the running loop."""
        if self._master >= 0:
            raise UsageError("this PtyServer is already serving")
        loop = asyncio.get_running_loop()
        self._master, self._slave = os.openpty()
        try:
            self.path = os.ttyname(self._slave)
            tty.setraw(self._slave)
            for speed in reversed(_BASELINE_SPEEDS):  # the first one stays set
                attrs = termios.tcgetattr(self._slave)
                attrs[_LFLAG] |= _EXTPROC
                attrs[_ISPEED] = attrs[_OSPEED] = speed
                termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
                self._baselines.insert(0, termios.tcgetattr(self._slave))
            fcntl.ioctl(self._master, _TIOCPKT, struct.pack("i", 1))
            os.set_blocking(self._master, False)
            if self.link:
                _replace_link(self.path, self.link)
        except (OSError, termios.error) as exc:
            self._close_fds()
            raise PortError(f"cannot serve a pty: {exc}") from exc
        except BaseException:  # the link refused: still no descriptors left behind
            self._close_fds()
            raise
        loop.add_reader(self._master, self._on_readable)
        self._start_pump()

    async def close(self) -> None:
        """Stop serving, close the pty and remove the link; safe to call twice."""
        if self._master < 0:
            return
        asyncio.get_running_loop().remove_reader(self._master)
        if self._pump is not None:
            self._pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._pump
            self._pump = None
        self._remove_link()
        self._close_fds()

    # -- receiving ------------------------------------------------------------------------

    def _on_readable(self) -> None:
        try:
            packet = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # cannot happen while we hold the slave open; do not spin on it
            asyncio.get_running_loop().remove_reader(self._master)
            return
        if not packet:
            return
        if packet[0] == _TIOCPKT_DATA:
            if len(packet) > 1:
                self.line.write(packet[1:])
                self._wake()
        elif packet[0] & _TIOCPKT_IOCTL:
            self._restore_baseline()

    def _restore_baseline(self) -> None:
        """Put a baseline back after a client changed the termios (see the module docstring).

        The client's speed is what its line runs at: the simulated line hears it (a wrong
        baud rate garbles every character). Parity cannot be told this way: Linux drops
        PARENB from a pty's termios.
        """
        try:
            attrs = termios.tcgetattr(self._slave)
            if attrs not in self._baselines:  # not our own change
                self.line.hear_master_at(_baud_of(self._slave, attrs[_OSPEED]))
                self._baseline ^= 1
                termios.tcsetattr(self._slave, termios.TCSANOW, self._baselines[self._baseline])
        except termios.error:
            pass  # a client's odd settings must not take the server down

    # -- sending --------------------------------------------------------------------------

    def _wake(self) -> None:
        due = self.line.next_delivery()
        if due is None:
            return
        if self._pump_until is None:
            self._idle.set()
        elif due < self._pump_until:
            assert self._pump is not None
            self._pump.cancel()
            self._start_pump()

    def _start_pump(self) -> None:
        self._pump_until = None
        self._pump = asyncio.get_running_loop().create_task(
            self._run_pump(), name=f"sim.pty[{self.path}].pump"
        )

    async def _run_pump(self) -> None:
        line = self.line
        while True:
            due = line.next_delivery()
            if due is None:
                self._pump_until = None
                self._idle.clear()
                await self._idle.wait()
                continue
            self._pump_until = due
            await self._clock.sleep_until(due)
            data = line.receive()
            if data:
                try:
                    os.write(self._master, data)
                except BlockingIOError:
                    self.overruns += len(data)

    def _remove_link(self) -> None:
        # Only a link still pointing at this pty: another server may have taken the name.
        if self.link and os.path.islink(self.link) and os.readlink(self.link) == self.path:
            os.unlink(self.link)

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1


def _replace_link(target: str, link: str) -> None:
    """Point ``link`` at ``target``; only a dangling symlink (a killed server's) is replaced.

    A link that leads somewhere may be a real adapter's (``/dev/serial/by-id/…``) or another
    server's pty: taking it over would hide that device, and removing it on exit lose it.
    """
    if os.path.lexists(link) and not os.path.islink(link):
        raise PortError(f"{link} exists and is not a symbolic link; not replacing it")
    if os.path.exists(link):  # follows the link: it leads to something
        raise PortError(
            f"{link} already links to {os.path.realpath(link)}; not replacing it "
            "(remove it, or simulate the line at another path)"
        )
    temporary = f"{link}.{os.getpid()}.tmp"
    os.symlink(target, temporary)
    os.replace(temporary, link)
