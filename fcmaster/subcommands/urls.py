"""The ``--url`` of a running daemon, as the commands that talk to one take it."""

from __future__ import annotations

from urllib.parse import SplitResult, urlsplit

from fcmaster.errors import UsageError


def daemon_url(url: str, schemes: tuple[str, ...]) -> SplitResult:
    """``url`` (``host:port`` means ``http://host:port``) split; UsageError if it is not one.

    A URL whose host or port cannot be read (``http://[::1``, ``http://host:99999``) is
    the user's mistake, said as such rather than found when the request is sent.
    """
    try:
        parts = urlsplit(url if "://" in url else f"http://{url}")
        _ = parts.port  # ValueError for a port that is not a number in 0-65535
    except ValueError:
        parts = None
    if parts is None or parts.scheme not in schemes or not parts.hostname:
        raise UsageError(f"--url {url!r} is not like http://127.0.0.1:8080")
    return parts
