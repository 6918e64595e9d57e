"""Scene-file keys derived from config dataclasses: a parameter, its type and its default are declared once, in
the dataclass; the schema of the TOML section that sets it is read from `dataclasses.fields`."""
from __future__ import annotations

import dataclasses
import typing

# annotation -> the TOML value types it accepts (TOML has no None: an optional parameter is simply left out)
_TOML_TYPES = {float: (int, float), int: int, bool: bool, str: str, tuple: list, list: list, dict: dict}


def _toml_types(annotation) -> type | tuple:
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _toml_types(args[0])
    return _TOML_TYPES[origin or annotation]


def schema_of(cls, exclude: tuple[str, ...] = ()) -> dict[str, tuple[type | tuple, bool]]:
    """{key: (TOML types, required)} of the fields of dataclass `cls` (required: no default)."""
    hints = typing.get_type_hints(cls)
    return {f.name: (_toml_types(hints[f.name]),
                     f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING)
            for f in dataclasses.fields(cls) if f.name not in exclude and not f.name.startswith("_")}


def from_table(cls, table: dict, exclude: tuple[str, ...] = ()):
    """An instance of dataclass `cls` from a validated TOML table (lists become tuples where the field is a
    tuple); keys in `exclude` (e.g. a section's `type`) are left out."""
    hints = typing.get_type_hints(cls)
    values = {}
    for key, value in table.items():
        if key in exclude:
            continue
        annotation = hints[key]
        target = typing.get_origin(annotation) or annotation
        if typing.get_origin(annotation) in (typing.Union, getattr(__import__("types"), "UnionType", None)):
            target = typing.get_origin(typing.get_args(annotation)[0]) or typing.get_args(annotation)[0]
        values[key] = tuple(value) if target is tuple and isinstance(value, list) else value
    return cls(**values)
