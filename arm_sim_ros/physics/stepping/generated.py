"""Generated code made once per process: the compiled text of each generated right-hand side
and step (every simulator of a scene structure, and a sweep builds thousands, execs the same
code), and a fixed-step method's step for each state it steps (a pure function, shared)."""
from __future__ import annotations

from functools import lru_cache

SHARED = 256        # steps kept (a sweep varying a decay rate makes one per value: bounded)
_SHARED: dict = {}


@lru_cache(maxsize=512)
def source_code(source: str, name: str):
    """compile(source, name), once per text."""
    return compile(source, name, "exec")


def shared(key, make):
    """make() the first time `key` is asked in this process, the same object after (of the
    last SHARED keys asked: the oldest is forgotten first)."""
    made = _SHARED.pop(key, None)
    if made is None:
        made = make()
        if len(_SHARED) >= SHARED:
            del _SHARED[next(iter(_SHARED))]
    _SHARED[key] = made
    return made
