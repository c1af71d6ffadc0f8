"""Compile one cffi extension; run as a child process by :mod:`symvi.build.ccompile`.

cffi's ``ffi.compile`` changes the process's working directory and the compiler writes
to the process's stdout/stderr, both process-wide: done here, in a process of its own,
neither can disturb the caller's threads. Usage::

    python _cffi_build.py SPEC.json

SPEC names the module, the files holding the cdef and the C source, the compile
arguments and libraries, the build folder and the file to write the built extension's
path into. Imports only the standard library and cffi (the script is run by path, not
as part of the symvi package, so that SymPy is never imported).
"""
import json
import os
import signal
import sys
import threading

import cffi


def _die_with_parent() -> None:
    """Kill this process group (the compiler included) when the parent goes away.

    The parent holds the write end of the pipe that is our stdin and never writes to
    it: end of file means the parent has exited or was killed, and a compile nobody
    waits for must not go on writing into a scratch folder the next build removes.
    """
    while os.read(0, 4096):   # unbuffered: a daemon thread must hold no lock at exit
        pass
    os.killpg(os.getpgrp(), signal.SIGKILL)


def main(spec_path: str) -> None:
    with open(spec_path) as handle:
        spec = json.load(handle)
    with open(spec["cdef"]) as cdef, open(spec["source"]) as source:
        ffi = cffi.FFI()
        ffi.cdef(cdef.read())
        ffi.set_source(spec["module"], source.read(), extra_compile_args=spec["args"],
                       libraries=spec["libraries"])
    built = ffi.compile(tmpdir=spec["tmpdir"], verbose=spec["verbose"])
    with open(spec["result"], "w") as handle:
        handle.write(built)


if __name__ == "__main__":
    threading.Thread(target=_die_with_parent, daemon=True).start()
    try:
        main(sys.argv[1])
    except Exception as exc:  # cffi wraps setuptools' errors in several types
        print(f"{type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
