"""A kernel's first compile, in a process of its own.

numba keeps everything a compile made (the LLVM modules of the function and of every callee
linked into it, the typing and lowering records) for the life of the process that compiled
it: about 40 MB a scene structure, never given back. A kernel loaded from the cache costs
about 2 MB. So where a kernel function meets a signature the cache does not hold, a child
process (this interpreter, the same module file) compiles it, and numba writes the machine
code to the cache as it always does; this process then loads it from there. The child's
memory goes with it.

The rest is numba's own path: the same module, the same signature, the same cache entry
(numba's cache files are keyed by the function's byte code and the signature, not by the
process), so the machine code is the same as a compile here would make. numba's compile
event still fires around the child's compile (the notice and the timing of cache.py hear
it). Where the child cannot do it (it fails, or the cache does not take its entry), the
compile happens here, as before; an error of the function is then numba's own.
"""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
import threading

# The child: the module at PATH under NAME, FUNCTION compiled for the pickled signature on
# stdin, ended by the kernel when this process ends (PR_SET_PDEATHSIG, Linux).
CHILD = """import ctypes, importlib.util, os, pickle, signal, sys
try:
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)
except (OSError, AttributeError):
    pass
if os.getppid() != int(sys.argv[4]):
    sys.exit(3)
name, path, function = sys.argv[1:4]
signature = pickle.load(sys.stdin.buffer)
spec = importlib.util.spec_from_file_location(name, path)
module = importlib.util.module_from_spec(spec)
sys.modules[name] = module
spec.loader.exec_module(module)
from arm_sim_ros.physics.compiled.entries import check_entries
check_entries(module)        # its files sealed as this process reads them (entries.py)
getattr(module, function).compile(signature)
"""
_here = threading.local()    # compiles under way in this thread, in this process


class CompiledApart(Exception):
    """The child wrote the signature's machine code to the cache: load it from there."""


class Compiler:
    """numba's compiler of one dispatcher (a stand-in for dispatcher._compiler, which numba
    calls only where the cache held nothing): the child compiles first; a compile nested in
    one under way here (a callee), or one the child could not make, is numba's, here."""

    def __init__(self, dispatcher, module):
        self.real, self.module, self.dispatcher = dispatcher._compiler, module, dispatcher
        self.tried = {}          # {signature: children that compiled it (2: one failed)}

    def __getattr__(self, name):
        return getattr(self.real, name)

    def compile(self, args, return_type):
        # a second child where the first compiled but the cache lost its entry: numba
        # rewrites a function's index whole, and another process may have written it meanwhile
        tries = self.tried.get(args, 0)
        if getattr(_here, "depth", 0) == 0 and return_type is None and tries < 2:
            if in_child(self.module, self.dispatcher.py_func.__name__, args):
                self.tried[args] = tries + 1
                raise CompiledApart
            self.tried[args] = 2
        _here.depth = getattr(_here, "depth", 0) + 1
        try:
            return self.real.compile(args, return_type)
        finally:
            _here.depth -= 1


def in_child(module, function: str, args) -> bool:
    """True where a child process compiled `function` of `module` for `args` (numba wrote
    it to the cache)."""
    import numba
    site = os.path.dirname(os.path.dirname(numba.__file__))     # where this numba lives
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [site, *filter(None, [os.environ.get("PYTHONPATH")])]))
    try:   # a session of its own: a Ctrl-C is this process's to act on (a stop between
        # steps lets the compile end; an exception here ends the child: subprocess.run)
        done = subprocess.run([sys.executable, "-c", CHILD, module.__name__, module.__file__,
                               function, str(os.getpid())], input=pickle.dumps(args),
                              capture_output=True, env=env, check=False,
                              start_new_session=True)
    except OSError:
        return False
    return done.returncode == 0


def compile_apart(module) -> None:
    """Each numba function of a kernel `module` compiles a signature first met in a child
    process (module docstring)."""
    from numba.core.registry import CPUDispatcher
    for dispatcher in vars(module).values():
        if isinstance(dispatcher, CPUDispatcher) and not isinstance(dispatcher._compiler,
                                                                    Compiler):
            dispatcher._compiler = Compiler(dispatcher, module)
            dispatcher.compile = _retried(dispatcher.compile)


def _retried(compile):
    """Dispatcher.compile that loads from the cache what a child compiled (at most two
    children a signature: Compiler.compile)."""
    def compile_loaded(signature):
        while True:
            try:
                return compile(signature)
            except CompiledApart:
                continue
    return compile_loaded
