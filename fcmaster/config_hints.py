"""Config problems in words: no secret shown, and 'did you mean'.

A misspelled key or choice gets the nearest known one; a problem with a secret never shows
its value. (YAML syntax errors in words: :func:`fcmaster.config_yaml.yaml_problem`.)
"""

from __future__ import annotations

import re
import types
import typing
from typing import Any

from pydantic import BaseModel

from fcmaster.config_yaml import describe_error
from fcmaster.suggest import did_you_mean

# Keys whose values are secrets: a problem with one never shows the value (it would reach
# a terminal, a log and the journal).
SECRET_KEYS = frozenset(("token", "password"))
_USERINFO = re.compile(r"(?<=://)[^/@\s]*@")


def in_words(model: type[BaseModel], error: Any) -> tuple[str, str]:
    """One of pydantic's errors as ``(key path, reason)``: no secret, the nearest key or choice."""
    loc = [p for p in error["loc"] if not (isinstance(p, str) and p.startswith("function-"))]
    given = error.get("input")
    keys = [p for p in loc if isinstance(p, str)]
    if keys and keys[-1] in SECRET_KEYS and error["type"] not in ("missing", "extra_forbidden"):
        where, _ = describe_error(error)
        return where, f"{error['msg'].lower()} (the value is a secret: not shown)"
    if isinstance(given, str) and _USERINFO.search(given):  # a URL with credentials in it
        error = {**error, "input": _USERINFO.sub("***@", given)}
    problem = describe_error(error)
    hint = ""
    if error["type"] == "extra_forbidden" and loc:
        hint = did_you_mean(str(loc[-1]), _keys_at(model, loc[:-1]))
    elif error["type"] == "literal_error" and isinstance(given, str):
        expected = str(error.get("ctx", {}).get("expected", ""))
        hint = did_you_mean(given, re.findall(r"'([^']*)'", expected))
    return problem[0], problem[1] + hint


def _keys_at(model: type[BaseModel], loc: list[int | str]) -> tuple[str, ...]:
    """The keys the mapping at ``loc`` may have (none known: empty)."""
    current: type[BaseModel] | None = model
    for part in loc:
        if isinstance(part, int):
            continue  # an item of a list: its model is the list's
        field = current.model_fields.get(part) if current else None
        current = _model_in(field.annotation) if field else None
    return tuple(current.model_fields) if current else ()


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The model a field holds, through ``list[…]`` and ``… | None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (list, typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            found = _model_in(arg)
            if found is not None:
                return found
    return None
