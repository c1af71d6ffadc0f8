"""Compile one cffi extension; run as a child process by :mod:`symvi.build.ccompile`.

cffi's ``ffi.compile`` changes the process's working directory and the compiler writes
to the process's stdout/stderr, both process-wide: done here, in a process of its own,
neither can disturb the caller's threads. Usage::

    python _cffi_build.py SPEC.json

SPEC names the module, the file holding the cdef, the translation units (C files,
compiled in parallel), the object files compiled before to link in, the compile arguments
of the units and of cffi's wrappers (a unit of their own) and the libraries, the build
folder and the file to write the built extension's path into;
or, with ``objects_only``, the one unit to compile to an object file (the generic
library) and the file to write that object's path into. Imports only the standard
library and cffi (the script is run by path, not as part of the symvi package, so that
SymPy is never imported).
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


def compile_units(units: list[str], args: list[str], folder: str) -> list[str]:
    """Compile the translation units ``units`` (paths of C files) to object files in
    ``folder``, as many at once as this process may use cores, with the compiler and flags
    cffi's build uses (distutils' compiler for this Python, customised as ``build_ext``
    does); the object files, in the order of ``units``."""
    import setuptools  # noqa: F401  (first: its distutils, as cffi does)
    from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
    from distutils.ccompiler import new_compiler
    from distutils.sysconfig import customize_compiler

    def compiler():
        # here, not in the threads: distutils reads the configuration variables into a
        # cache that concurrent first readers see half filled
        made = new_compiler()
        customize_compiler(made)
        return made

    def one(job) -> str:
        path, made = job
        return made.compile([path], output_dir=folder, extra_postargs=args)[0]

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    largest_first = sorted(units, key=os.path.getsize, reverse=True)
    jobs = [(path, compiler()) for path in largest_first]
    with ThreadPoolExecutor(max_workers=max(1, cores or 1)) as pool:
        futures = {pool.submit(one, job): job[0] for job in jobs}
        done, _ = wait(futures, return_when=FIRST_EXCEPTION)
        failed = [f for f in done if f.exception() is not None]
        if failed:      # the first error ends the build: the units not started never start
            for future in futures:
                future.cancel()
            raise failed[0].exception()
        built = {futures[f]: f.result() for f in futures}
    return [built[path] for path in units]


def main(spec_path: str) -> None:
    with open(spec_path) as handle:
        spec = json.load(handle)
    if spec.get("objects_only"):    # object files to link later (the generic library)
        objects = compile_units(spec["units"], spec["args"], spec["tmpdir"])
        with open(spec["result"], "w") as handle:
            handle.write(os.path.abspath(objects[0]))
        return
    with open(spec["cdef"]) as cdef:
        declarations = cdef.read()
    # the model's units compiled side by side, cffi's wrappers in a unit of their own
    # (the prototypes of the functions they call) with flags of their own
    objects = compile_units(spec["units"], spec["args"], os.path.join(spec["tmpdir"], "units"))
    ffi = cffi.FFI()
    ffi.cdef(declarations)
    ffi.set_source(spec["module"], declarations, extra_compile_args=spec["wrapper_args"],
                   libraries=spec["libraries"], extra_objects=objects + spec["link"])
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
