"""The digest of the emitted C (every translation unit and the cffi declarations) of every
bundled model, one line each: ``name digest``.

A refactoring that must not change the generated code (issue 49) compares two runs:

    python scripts/emitted_digests.py > before.txt    # on the old commit
    python scripts/emitted_digests.py > after.txt     # on the new one
    diff before.txt after.txt

Discretises, derives and emits only (no C compiler), in worker processes.
"""
from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

from symvi.codegen.emit import emit
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.models import BUNDLED, get


def digest(name: str) -> str:
    """The emitted sources' digest of the bundled model ``name``."""
    return emit(derive(discretise(get(name)))).digest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("models", nargs="*", default=sorted(BUNDLED))
    args = parser.parse_args()
    with ProcessPoolExecutor(args.workers) as pool:
        for name, value in zip(args.models, pool.map(digest, args.models)):
            print(name, value, flush=True)


if __name__ == "__main__":
    main()
