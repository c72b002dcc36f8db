"""A scene file's errors as one line each: pydantic's error located by the user's keys.

Used by :mod:`invsss.scenes.config`; the messages name the key as a dotted path as
it stands in the TOML file, the closest valid key for a misspelt one, and what
was expected.
"""

from __future__ import annotations

import difflib
import json
from typing import TYPE_CHECKING, Literal, get_args, get_origin

from pydantic import BaseModel

if TYPE_CHECKING:
    from pydantic_core import ErrorDetails

__all__ = ["pydantic_error_line"]


def pydantic_error_line(error: ErrorDetails, name: str, root: type[BaseModel]) -> str:
    """One line for a pydantic error of the model ``root``: the key as a dotted path,
    what was expected (``name``: the file, first in the line)."""
    model, path, union = _walk(list(error["loc"]), root)
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path).lstrip(".")
    kind = error["type"]
    if union and kind in ("float_type", "list_type", "greater_than", "greater_than_equal"):
        return f"{name}: {where}: expected a number or a list of 3 numbers (RGB), got {_shown(error.get('input'))}"
    if kind == "extra_forbidden":
        valid = list(model.model_fields)
        nearest = difflib.get_close_matches(str(path[-1]), valid, n=1, cutoff=0.0)
        hint = f", did you mean {nearest[0]!r}?" if nearest else ""
        return f"{name}: {where}: unknown key{hint} (valid: {', '.join(valid)})"
    if kind == "missing":
        return f"{name}: {where}: missing"
    if kind in ("int_type", "float_type", "bool_type", "string_type"):
        expected = {"int_type": "an integer", "float_type": "a number",
                    "bool_type": "true or false", "string_type": "a string"}[kind]
        return f"{name}: {where}: expected {expected}, got {_shown(error.get('input'))}"
    if kind == "union_tag_invalid":
        given = error.get("input", {}).get("type") if isinstance(error.get("input"), dict) else None
        return f"{name}: {where}.type: expected one of {error['ctx']['expected_tags']}, got {_shown(given)}"
    if kind == "union_tag_not_found":
        return f"{name}: {where}: missing type (point, spot, area or directional)"
    message = error["msg"].removeprefix("Value error, ")
    message = message[0].lower() + message[1:]
    if kind in ("value_error", "assertion_error"):
        return f"{name}: {where}: {message}"
    return f"{name}: {where}: {message}, got {_shown(error.get('input'))}"


def _walk(loc: list, root: type[BaseModel]) -> tuple[type[BaseModel], list, bool]:
    """Follow pydantic's error location through the models.

    Returns the model that holds the last key, the location as the user wrote
    it (list indices and keys kept, the labels pydantic adds for union members, a
    light's ``"point"`` or a number's ``"float"``, dropped) and whether the value
    was one of a union of plain types (a number or a list of numbers).
    """
    model: type[BaseModel] = root
    path: list = []
    inside = None  # the annotation of the field the location has entered
    union = False
    for part in loc:
        if isinstance(part, int):
            path.append(part)
            continue
        if inside is not None:
            members = _models_in(inside)
            tags = {_tag(m): m for m in members if _tag(m) is not None}
            if part in tags:
                model, inside = tags[part], None
                continue
            if len(members) != 1:
                union = union or not members
                continue  # a union member's label, not a key
            model, inside = members[0], None
        path.append(part)
        if part not in model.model_fields:
            break
        inside = model.model_fields[part].annotation
    return model, path, union


def _models_in(annotation) -> list[type[BaseModel]]:
    """The pydantic models an annotation can hold (through list, Optional, Union, Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    found: list[type[BaseModel]] = []
    for arg in get_args(annotation):
        found += _models_in(arg)
    return found if get_origin(annotation) is not Literal else []


def _tag(model: type[BaseModel]) -> str | None:
    field = model.model_fields.get("type")
    if field is None or get_origin(field.annotation) is not Literal:
        return None
    return get_args(field.annotation)[0]


def _shown(value) -> str:
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)
