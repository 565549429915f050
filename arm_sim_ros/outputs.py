"""One rule for every file a command writes (--csv, --bag, --rerun, --json, --plot), checked
before any work starts: an existing file or directory is refused unless --force, an
unwritable place is refused, and a forced replacement removes a symlink itself, never
writes through it. Devices and pipes (/dev/stdout, /dev/null, a FIFO) are written to as
they are.
"""
from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

from .usage import UsageError

BAG_FILES = (".mcap", ".db3", ".yaml")      # what --force may remove from a bag directory


def check_output(path: str, option: str, force: bool = False, directory: bool = False,
                 suffixes: tuple = ()) -> Path:
    """`path` if a command may write it; UsageError (one line) saying why not."""
    if not path:
        raise UsageError(f"{option} needs a path")
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes and not _is_stream(p):
        raise UsageError(f"{option} {path}: the name must end in {' or '.join(suffixes)}")
    if os.path.lexists(p) and not _is_stream(p):
        if not force:
            raise UsageError(f"{option} {path} exists already; choose a new name, or add "
                             "--force to replace it")
        if p.is_dir() and not p.is_symlink():
            if not directory:
                raise UsageError(f"{option} {path} is a directory; give a file name")
            if any(not (c.is_file() and c.suffix in BAG_FILES) for c in p.iterdir()):
                raise UsageError(f"{option} {path} holds more than a bag's files; --force "
                                 "replaces only a bag, choose a new name")
    parent = p.parent
    if not parent.is_dir():
        raise UsageError(f"{option} {path}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: the directory {parent} is not writable")
    return p


def claim_output(path, option: str) -> bool:
    """Create `path` empty, exclusively (O_EXCL): of two runs naming the same file, the
    second is refused in one line instead of splicing its rows into the first's. False for a
    device or pipe, which is written as it is (nothing claimed)."""
    p = Path(path)
    if _is_stream(p):
        return False
    try:
        os.close(os.open(p, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
    except FileExistsError:
        raise UsageError(f"{option} {path} was created by another run meanwhile; choose a "
                         "new name") from None
    except OSError as error:
        raise UsageError(f"{option} {path}: cannot write: {error.strerror}") from None
    return True


def clear_output(path) -> None:
    """Remove what --force replaces: a file, a symlink (not its target) or a bag directory."""
    p = Path(path)
    if _is_stream(p) or not os.path.lexists(p):
        return
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink()


def write_text(path, text: str, option: str) -> None:
    """Write the whole text or nothing: a full disk leaves no half file behind."""
    p = Path(path)
    if _is_stream(p):
        with open(p, "w") as stream:
            stream.write(text)
        return
    partial = p.with_name(f".{p.name}.partial")
    try:
        with open(partial, "w") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(partial, p)
    except OSError as error:
        partial.unlink(missing_ok=True)
        raise UsageError(f"{option} {path}: cannot write: {error.strerror}") from None


def strict_json(value, **options) -> str:
    """JSON as RFC 8259 has it: a number that is not finite becomes null."""
    return json.dumps(_finite_or_none(value), allow_nan=False, **options)


def _finite_or_none(value):
    if isinstance(value, float):
        return value if value - value == 0.0 else None
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    return value


def _is_stream(p: Path) -> bool:
    try:
        mode = os.stat(p).st_mode
    except (OSError, ValueError):      # ValueError: a NUL in the name (no such file either)
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)
