"""The drives' side of a capture, played back: a field problem reproduced at a desk.

Each line of a capture (a pcapng interface) becomes a :class:`SimLine` with one
:class:`ReplayDrive` that knows every request the master sent and what came back after it:
the bytes the master read until its next request (a reply, a late reply, noise), or
nothing (a timeout). A request heard again is answered with what followed it the next
time in the capture, in order; after the last time, as the last time. A request never
captured gets no answer, as from a drive that is not there.

The answer starts after the captured turnaround: the time from the request to the reply's
last byte less both frames' wire time at the captured baud rate (never below the
protocol's shortest). That keeps slow drives slow and a USB adapter's latency in the
capture, so a deadline that was too short in the field is too short at the desk.

Requests are recognised by their bytes alone, not by the protocol's framer, so a replay
needs no settings of the drives (Mitsubishi's Pr.123 and Pr.124 among them) — except where
the protocol has :class:`~fcmaster.sim.simulator.ReplayRules`. A request then also gets
what the capture implies: the answer its *question* got (an FC telegram's parameter part,
whatever control word and reference it carries, so a commissioning tool's zero control
word or a daemon's start-up telegrams are answered too), and a request for a drive's
status alone is answered from that drive's latest captured answer. Only a question the
capture never asked of a drive (a parameter it never read) stays unanswered.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass

from fcmaster.clock import Clock
from fcmaster.errors import UsageError
from fcmaster.protocol import pcapng
from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from fcmaster.protocol.pcapng import Capture, LineFormat
from fcmaster.sim.build import SIM_PROTOCOLS
from fcmaster.sim.line import RequestFramer, SimLine
from fcmaster.sim.settings import LineSettings
from fcmaster.sim.simulator import ReplayRules

MIN_TURNAROUND_S = 0.001

# The bytes that came back after one request (None: nothing came), and how long after.
Answer = tuple[bytes | None, float]
# Told of each request heard and its answer (None: none, or a request not captured).
Served = Callable[[bytes, bytes | None], None]


@dataclass(slots=True, frozen=True)
class ReplayLine:
    """One captured line to serve: its name, its format, and what its drives answered."""

    name: str
    format: LineFormat
    answers: dict[bytes, list[Answer]]
    # every request and its answer, in the capture's order
    sequence: tuple[tuple[bytes, Answer], ...] = ()


def replay_lines(capture: Capture) -> list[ReplayLine]:
    """Every line in ``capture`` with the answers to each request it holds."""
    lines = []
    for index, interface in enumerate(capture.interfaces):
        protocol = pcapng.PROTOCOLS.get(interface.link_type)
        fmt = LineFormat.parse(interface.description)
        if protocol is None or fmt is None or fmt.protocol != protocol:
            raise UsageError(
                f"interface {index} ({interface.name or 'unnamed'}) is not a line fcmaster "
                f"captured: link type {interface.link_type}, {interface.description!r}"
            )
        packets = [p for p in capture.packets if p.interface == index]
        sequence = _sequence(packets, fmt)
        answers: dict[bytes, list[Answer]] = defaultdict(list)
        for request, answer in sequence:
            answers[request].append(answer)
        name = interface.name or f"line{index}"
        lines.append(ReplayLine(name, fmt, dict(answers), tuple(sequence)))
    if not lines:
        raise UsageError("the capture has no lines to replay")
    return lines


def _sequence(packets: list[pcapng.Packet], fmt: LineFormat) -> list[tuple[bytes, Answer]]:
    char_s = (1 + fmt.databits + (fmt.parity != "N") + fmt.stopbits) / fmt.baudrate
    answers: list[tuple[bytes, Answer]] = []
    request: pcapng.Packet | None = None
    reply = bytearray()
    last_us = 0

    def close() -> None:
        if request is None:
            return
        if not reply:
            answers.append((request.data, (None, 0.0)))
            return
        wire = (len(request.data) + len(reply)) * char_s
        turnaround = (last_us - request.timestamp_us) / 1e6 - wire
        answers.append((request.data, (bytes(reply), max(MIN_TURNAROUND_S, turnaround))))

    for packet in packets:
        if packet.direction == pcapng.OUTBOUND:
            close()
            request, reply = packet, bytearray()
        elif request is not None:
            reply += packet.data
            last_us = packet.timestamp_us
    close()
    return answers


class ReplayDrive:
    """Answers the requests of a capture as the drives did; a :class:`SimDrive`."""

    def __init__(
        self,
        answers: dict[bytes, list[Answer]],
        served: Served | None = None,
        *,
        rules: ReplayRules | None = None,
        sequence: Sequence[tuple[bytes, Answer]] = (),
    ) -> None:
        self._answers = answers
        self._next = dict.fromkeys(answers, 0)
        self._delay_s = MIN_TURNAROUND_S
        self._served = served
        self._rules = rules
        # With rules: the answers each question got, in order, and each drive's latest one.
        self._by_question: dict[Hashable, list[Answer]] = defaultdict(list)
        self._latest: dict[int, Answer] = {}
        for request, answer in sequence:
            if rules is None:
                break
            question, address = rules.question(request), rules.address(request)
            if answer[0] is None or question is None:
                continue  # a question once unanswered is answered when it was another time
            self._by_question[question].append(answer)
            if address is not None:
                self._latest[address] = answer
        self._next_by_question = dict.fromkeys(self._by_question, 0)

    @property
    def address(self) -> int:
        """Unused: the capture's drives answer for themselves."""
        return 0  # the capture's drives answer for themselves

    @property
    def response_delay_s(self) -> float:
        """The captured turnaround of the answer :meth:`handle` gave last."""
        return self._delay_s  # of the answer handle() returned last

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """What followed ``frame`` in the capture, the next time; None: nothing did."""
        answers = self._answers.get(frame)
        if answers is not None:
            index = self._next[frame]
            self._next[frame] = min(index + 1, len(answers) - 1)
            reply, self._delay_s = answers[index]
        else:
            reply = self._implied(frame)
        if self._served is not None:
            self._served(frame, reply)
        return reply

    def _implied(self, frame: bytes) -> bytes | None:
        """The answer the capture implies for a request it does not hold byte for byte."""
        if self._rules is None:
            return None
        question = self._rules.question(frame)
        answers = self._by_question.get(question) if question is not None else None
        if answers:
            index = self._next_by_question[question]
            self._next_by_question[question] = min(index + 1, len(answers) - 1)
            reply, self._delay_s = answers[index]
            return reply
        address = self._rules.address(frame)
        latest = self._latest.get(address) if address is not None else None
        if latest is None or latest[0] is None:
            return None  # a drive the capture never heard answer: not there
        reply = self._rules.answer(frame, latest[0])
        if reply is not None:
            self._delay_s = latest[1]
        return reply


class KnownRequestFramer:
    """Cuts out of the master's bytes exactly the requests a capture holds, and no others.

    Bytes that are no captured request are handed to ``unknown`` in one piece when the
    master pauses (a gap) or a known request follows them, so they can be shown.
    """

    def __init__(
        self, requests: list[bytes], unknown: Callable[[bytes], None] | None = None
    ) -> None:
        self._requests = set(requests)
        self._prefixes = {r[:n] for r in requests for n in range(1, len(r) + 1)}
        self._buffer = bytearray()
        self._gap = False
        self._unknown = unknown
        self._unheard = bytearray()  # skipped bytes not reported yet

    def feed(self, data: bytes) -> None:
        """Append the master's bytes."""
        self._buffer += data

    def reset(self) -> None:
        """A gap: an unfinished request is given up."""
        self._gap = bool(self._buffer)
        self._report(self._buffer)

    def _report(self, also: bytes | bytearray = b"") -> None:
        unheard = bytes(self._unheard + also)
        self._unheard.clear()
        if unheard and self._unknown is not None:
            self._unknown(unheard)

    def next_frame(self) -> Frame | Skipped | None:
        """The next known request, or bytes that cannot begin one."""
        buffer = self._buffer
        if self._gap:
            self._gap = False
            gone = bytes(buffer)
            buffer.clear()
            return Skipped(gone, SkipReason.GAP)
        for end in range(1, len(buffer) + 1):
            candidate = bytes(buffer[:end])
            if candidate in self._requests:
                del buffer[:end]
                self._report()
                return Frame(candidate)
        if not buffer or bytes(buffer) in self._prefixes:
            return None
        # Not the start of a known request: give up bytes until the rest may be one.
        for start in range(1, len(buffer) + 1):
            if bytes(buffer[start:]) in self._prefixes or start == len(buffer):
                gone = bytes(buffer[:start])
                del buffer[:start]
                self._unheard += gone
                return Skipped(gone, SkipReason.NOISE)
        return None  # pragma: no cover - the loop always returns


class ReportingFramer:
    """A protocol's own framer whose skipped bytes are reported, each run of them at once."""

    def __init__(self, framer: RequestFramer, unknown: Callable[[bytes], None]) -> None:
        self._framer = framer
        self._unknown = unknown
        self._skipped = bytearray()

    def feed(self, data: bytes) -> None:
        """Append the master's bytes."""
        self._framer.feed(data)

    def reset(self) -> None:
        """A gap: an unfinished request is given up (it comes out as skipped)."""
        self._framer.reset()

    def next_frame(self) -> Frame | Skipped | None:
        """The framer's next piece; skipped bytes are told before the next request."""
        piece = self._framer.next_frame()
        if isinstance(piece, Skipped):
            self._skipped += piece.data
        elif self._skipped:
            self._unknown(bytes(self._skipped))
            self._skipped.clear()
        return piece


def replay_sim_line(line: ReplayLine, *, clock: Clock, served: Served | None = None) -> SimLine:
    """A simulated line whose one drive replays ``line``'s answers."""
    fmt = line.format
    settings = LineSettings(
        name=line.name,
        protocol=fmt.protocol,
        baudrate=fmt.baudrate,
        parity=fmt.parity,
        stopbits=fmt.stopbits,
        databits=fmt.databits,
    )
    requests = list(line.answers)

    def unknown(data: bytes) -> None:
        if served is not None:
            served(data, None)

    rules = SIM_PROTOCOLS[fmt.protocol].replay if fmt.protocol in SIM_PROTOCOLS else None

    def framer() -> RequestFramer:
        if rules is None:
            return KnownRequestFramer(requests, unknown)
        return ReportingFramer(rules.framer(), unknown)

    return SimLine(
        drives=[ReplayDrive(line.answers, served, rules=rules, sequence=line.sequence)],
        framer_factory=framer,
        baudrate=fmt.baudrate,
        char_bits=settings.char_bits,
        clock=clock,
        parity=fmt.parity,
    )
