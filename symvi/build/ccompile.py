"""The C compile of the build stage, in a child process (:mod:`symvi.build._cffi_build`).

The cdef and the C source go to the child through files in the scratch folder; the
compiler's output comes back through the child's pipes and is shown in the
:class:`~symvi.errors.BuildError` of a failed build (or on stderr with ``verbose``).
Nothing here changes the working directory or the file descriptors of this process.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Sequence

from ..errors import BuildError
from .files import write_file

_CHILD = Path(__file__).resolve().with_name("_cffi_build.py")
# Run the child script by path (not ``-m symvi.build._cffi_build``, which would import symvi
# and SymPy) and without putting symvi's own folder first on the child's sys.path.
_BOOTSTRAP = ("import runpy, sys; sys.argv = sys.argv[1:]; "
              "runpy.run_path(sys.argv[0], run_name='__main__')")


class CompileTimeout(Exception):
    """The compiler was still running at the deadline (it has been killed)."""


def compile_extension(cdef: str, units: Sequence[tuple[str, str]], module: str,
                      workdir: Path, args: list[str], timeout: float | None = None,
                      verbose: bool = False, objects: Sequence[Path] = (),
                      wrapper_args: list[str] | None = None) -> Path:
    """Build the cffi extension ``module`` in ``workdir``; return its path.

    ``units`` are the translation units, (name, C text), compiled in parallel with
    ``args``; ``cdef`` declares the functions they export and is the C of the extension's
    own unit, which holds cffi's wrappers, compiled with ``wrapper_args`` (default
    ``args``); ``objects`` are object files compiled before (the generic library,
    :mod:`symvi.build.generic`), linked in.

    Raises :class:`BuildError` with the compiler's output if compilation fails and
    :class:`CompileTimeout` if it runs longer than ``timeout`` seconds.
    """
    workdir = Path(workdir).absolute()     # the child runs in it: relative paths would break
    spec = _write_inputs(cdef, units, module, workdir, args, verbose)
    spec["link"] = [str(Path(p).absolute()) for p in objects]
    spec["wrapper_args"] = list(args if wrapper_args is None else wrapper_args)
    sources = ", ".join(f"{module}_{name}.c" for name, _ in units)
    return Path(_run_spec(spec, workdir, timeout, verbose, f"{module} ({sources})"))


def compile_object(source: str, name: str, workdir: Path, args: list[str],
                   timeout: float | None = None, verbose: bool = False) -> Path:
    """Compile the C text ``source`` to the object file ``name``.o (position-independent,
    with the compiler and flags of the extensions it will be linked into) in ``workdir``;
    its path. Errors as :func:`compile_extension`'s."""
    workdir = Path(workdir).absolute()
    write_file(workdir / f"{name}.c", source)
    # the source by its name in the child's working folder: the object then records no
    # path of the (randomly named) folder it was compiled in
    spec = {"objects_only": True, "args": list(args), "verbose": verbose,
            "tmpdir": str(workdir / "build"), "result": str(workdir / "built.txt"),
            "units": [f"{name}.c"]}
    return Path(_run_spec(spec, workdir, timeout, verbose, f"{name}.c"))


def _run_spec(spec: dict, workdir: Path, timeout: float | None, verbose: bool,
              what: str) -> str:
    """Run the child on ``spec`` (written into ``workdir``); the text it leaves in the
    spec's result file (the path of what it built)."""
    if not sys.executable:
        raise BuildError("cannot run the C compile: the path of the Python interpreter "
                         "(sys.executable) is unknown")
    path = workdir / "spec.json"
    write_file(path, json.dumps(spec))
    returncode, output = _run_child([sys.executable, "-c", _BOOTSTRAP, str(_CHILD), str(path)],
                                    workdir, timeout)
    if verbose and output:
        print(output, file=sys.stderr, end="" if output.endswith("\n") else "\n")
    result = Path(spec["result"])
    if returncode != 0 or not result.is_file():
        raise BuildError(f"the C compile of {what} failed (exit status "
                         f"{returncode})\n--- compiler output ---\n{output.strip()}")
    return result.read_text()


def _write_inputs(cdef: str, units: Sequence[tuple[str, str]], module: str, workdir: Path,
                  args: list[str], verbose: bool) -> dict:
    cdef_path = workdir / "cdef.h"
    write_file(cdef_path, cdef)
    names = []
    for name, text in units:
        names.append(f"{module}_{name}.c")
        write_file(workdir / names[-1], text)
    # the units by their names in the child's working folder: the objects then record no
    # path of the (randomly named) scratch folder, and the extension is reproducible
    return {"module": module, "args": list(args), "libraries": ["m"], "verbose": verbose,
            "tmpdir": str(workdir / "build"), "result": str(workdir / "built.txt"),
            "cdef": str(cdef_path), "units": names}


def _run_child(command: list[str], workdir: Path, timeout: float | None) -> tuple[int, str]:
    """Run ``command`` in its own process group (so that the compiler, a grandchild, is
    killed with it); return its exit status and its merged stdout and stderr."""
    if timeout is not None and timeout <= 0:
        raise CompileTimeout()
    # The child's stdin is a pipe whose write end only this process holds: if this
    # process dies, the child sees end of file and kills itself and the compiler.
    lifeline, keep = os.pipe()
    try:
        child = subprocess.Popen(command, cwd=workdir, stdin=lifeline,
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 start_new_session=True, text=True, errors="replace")
    except OSError as exc:
        os.close(keep)
        raise BuildError(f"could not start the C compile ({command[0]}): "
                         f"{exc.strerror or exc}") from None
    finally:
        os.close(lifeline)
    try:
        output, _ = child.communicate(timeout=timeout)
    except BaseException as exc:   # the deadline, Ctrl-C, ...: no orphaned compiler
        _kill_group(child)
        if isinstance(exc, subprocess.TimeoutExpired):
            raise CompileTimeout() from None
        raise
    finally:
        os.close(keep)
    return child.returncode, output


def _kill_group(child: subprocess.Popen) -> None:
    try:
        os.killpg(child.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    child.communicate()
