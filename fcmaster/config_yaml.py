"""YAML text to checked data: ``${ENV_VAR}`` substitution and pydantic's errors in words.

Both report problems as ``(key path, reason)`` pairs, the form every config problem takes.
"""

from __future__ import annotations

import re
from typing import Any

_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def substitute(value: Any, path: str, env: Any, problems: list[tuple[str, str]]) -> Any:
    """``value`` with ``${VAR}`` (``${VAR:-default}``) replaced from ``env`` throughout.

    An unset variable without a default is a problem at ``path``'s key; it leaves a
    stand-in long enough to pass a token's length check, so that it is reported once.
    """
    if isinstance(value, str):

        def replace(match: re.Match[str]) -> str:
            name, default = match[1], match[2]
            if name in env:
                return str(env[name])
            if default is not None:
                return default
            problems.append((path or "(top)", f"environment variable {name} is not set"))
            return f"unset-{name}".ljust(_UNSET_LENGTH, "-")

        return _ENV.sub(replace, value)
    if isinstance(value, dict):
        return {k: substitute(v, _join(path, k), env, problems) for k, v in value.items()}
    if isinstance(value, list):
        return [substitute(v, f"{path}[{i}]", env, problems) for i, v in enumerate(value)]
    return value


_UNSET_LENGTH = 32  # an unset variable's stand-in passes a token's length check


def _join(path: str, key: object) -> str:
    return f"{path}.{key}" if path else str(key)


def _location(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out = f"{out}[{part}]" if isinstance(part, int) else _join(out, part)
    return out or "(top)"


def describe_error(error: Any) -> tuple[str, str]:
    """One of pydantic's errors as ``(key path, reason)``, in the words users read."""
    loc = tuple(p for p in error["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    kind, given = error["type"], error.get("input")
    if kind == "extra_forbidden":
        return _location(loc), "unknown key"
    if kind == "missing":
        return _location(loc), "required key is missing"
    if kind == "literal_error":
        expected = error.get("ctx", {}).get("expected", "")
        return _location(loc), f"{given!r} is not one of {expected}"
    return _location(loc), f"{error['msg'].lower()} (got {given!r})"
