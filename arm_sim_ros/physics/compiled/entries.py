"""The kernel cache's entries, checked as they are read: a damaged one is set aside and
compiled again, said in one line; never a traceback on this run and every later one.

An entry is a generated module (arm_sim_kernel_<hash>.py, build.load) and numba's files of
each of its functions in __pycache__: an index (.nbi, a pickle naming the object code of
each signature) and the object code (.nbc, a pickle). A full disk or a bad copy leaves them
truncated or garbage, and numba's own reader raises on every later run until a person
deletes the folder. Here each file numba writes is sealed with the SHA-256 of its pickle
(appended: pickle.loads ignores what follows a pickle, so a reader of this package's
older versions, sharing the cache, still reads it), and a file whose seal does not match,
or whose pickle does not load, is renamed <file>.damaged (the latest one kept for a look)
and read as absent: numba compiles the function again and writes it anew. A file with no
seal (written by an older version) is read as numba reads it, any failure set aside the
same way. A module file that is not the text its hash names is set aside and written anew
(build.load).
"""
from __future__ import annotations

import hashlib
import os
import pickle
import sys
from functools import lru_cache

SEAL = b"\n#arm_sim_ros sha256 "        # then the 64 hex digits of the pickle's SHA-256
SEALED = len(SEAL) + 64
SAID: set = set()                     # the caches whose damage a line has said


@lru_cache(maxsize=None)
def say_once(line: str) -> None:
    """A line on stderr, once a process (stderr as it is then: a test's, a redirect)."""
    print(line, file=sys.stderr)


class Damaged(OSError):
    """A cache file that cannot be what it claims; its message says why."""


def seal(data: bytes) -> bytes:
    return data + SEAL + hashlib.sha256(data).hexdigest().encode()


def unsealed(data: bytes) -> bytes:
    """The pickle of a file's `data`, its seal checked (Damaged if it does not match); a
    file with no seal is returned whole."""
    if data[-SEALED:-64] != SEAL:
        return data
    body, digest = data[:-SEALED], data[-64:]
    if hashlib.sha256(body).hexdigest().encode() != digest:
        raise Damaged("its SHA-256 does not match: the file was cut short or overwritten")
    return body


def set_aside(path: str, why) -> None:
    """Rename a damaged cache file to <path>.damaged and say so: one line a cache a process,
    naming the first (a disk that filled damages many files, of many modules, alike)."""
    try:
        os.replace(path, f"{path}.damaged")
    except OSError:
        pass                              # gone already (another process set it aside)
    directory, name = os.path.split(path)
    cache = directory.removesuffix(f"{os.sep}__pycache__")
    if cache not in SAID:
        SAID.add(cache)
        why = " ".join(str(why).split())        # LLVM's errors run over several lines
        print(f"arm_sim_ros: the kernel cache {cache} held a damaged entry ({name}: {why}; "
              "any more alike are not named); set aside as *.damaged and compiled again",
              file=sys.stderr)


def reason(error: BaseException) -> str:
    return str(error) if isinstance(error, Damaged) else f"{type(error).__name__}: {error}"


@lru_cache(maxsize=None)
def checked_classes():
    """(CacheFile, FunctionCache): numba's, sealing what they write and setting aside what
    they cannot read. Made once, on first use: numba is imported only on the compiled path."""
    from numba.core import caching

    class CacheFile(caching.IndexDataCacheFile):
        def _dump(self, obj):
            return seal(super()._dump(obj))

        def _load_index(self):
            try:
                with open(self._index_path, "rb") as file:
                    version = pickle.load(file)
                    data = file.read()
                if version != self._version:
                    return {}                 # another numba's: numba's own rule
                stamp, overloads = pickle.loads(unsealed(data))
                if not isinstance(overloads, dict):
                    raise Damaged("its pickle is not an index")
            except FileNotFoundError:
                return {}
            except Exception as error:    # a pickle cut short or garbage, a broken seal
                set_aside(self._index_path, reason(error))
                return {}
            return overloads if stamp == self._source_stamp else {}

        def _load_data(self, name):
            path = self._data_path(name)
            try:
                with open(path, "rb") as file:
                    return pickle.loads(unsealed(file.read()))
            except FileNotFoundError:
                raise
            except Exception as error:
                set_aside(path, reason(error))
                raise Damaged(reason(error)) from None   # numba's load: an absent entry

    class FunctionCache(caching.FunctionCache):
        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception as error:    # an unsealed entry that loads but will not rebuild
                set_aside(self._cache_file._index_path, reason(error))
                return None

        def save_overload(self, sig, data):
            try:
                super().save_overload(sig, data)
            except OSError as error:      # a full disk: compiled for this run only
                say_once(f"arm_sim_ros: cannot write the kernel cache in {self._cache_path} "
                         f"({error.strerror or error}); this run's kernels are compiled for "
                         "it alone")

    return CacheFile, FunctionCache


def check_entries(module) -> None:
    """Give every numba function of a kernel module the checked cache (class swapped: the
    same state, only the reading and writing differ)."""
    cache_file, function_cache = checked_classes()
    for value in vars(module).values():
        cache = getattr(value, "_cache", None)
        if type(cache).__name__ == "FunctionCache" and not isinstance(cache, function_cache):
            cache.__class__ = function_cache
            cache._cache_file.__class__ = cache_file
