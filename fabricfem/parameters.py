"""Declared-once parameters: a dataclass field carrying its documentation (meaning and SI unit) next to its
default, so that the scene reference (docs/scenes.md) and the scene schema are read from the same declaration."""
from __future__ import annotations

import dataclasses


def param(text: str, default=dataclasses.MISSING, **kw):
    """A dataclass field documented by `text` (meaning and unit); no default makes it required."""
    return dataclasses.field(default=default, metadata={"doc": text}, **kw)


def param_doc(f: dataclasses.Field) -> str:
    """The documentation of a field declared with `param` ("" otherwise)."""
    return f.metadata.get("doc", "")
