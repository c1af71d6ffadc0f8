"""The order and the grouping of a kernel's straight-line C, chosen so that large kernels
compile in bounded time and memory.

A kernel is a list of temporaries (common subexpressions) and output assignments. Printed
as CSE returns them, every temporary is computed before the first output, so thousands of
values are live at once; gcc's register allocator is superlinear in that number (the
20-link chain's whole-trajectory kernel, 1200 Jacobian entries and 5000 temporaries: 19 s
and 570 MB of its 29 s compile, 60 % of it in register assignment). Here

* each temporary is computed just before the first statement that needs it (outputs keep
  their order), which shortens live ranges, and
* a kernel of more than :data:`SPLIT_ABOVE` statements is cut into parts of
  :data:`PART` statements, each a function of its own (not inlined); a value one part
  computes and a later one uses passes through a work array ``w`` whose slots are reused
  once their value is dead.

The arithmetic is unchanged, operation for operation: the compiled kernel gives the same
bits, only sooner. Measured (gcc 12, -O2 -fno-tree-slp-vectorize): that kernel 19 s and
570 MB → 5 s and 125 MB; the chain's whole source 29 s → 9 s.
"""
from __future__ import annotations

from dataclasses import dataclass

#: Kernels with more statements than this are split into parts.
SPLIT_ABOVE = 1500
#: Statements per part of a split kernel.
PART = 60


@dataclass(frozen=True)
class Statement:
    """``target = code``: a temporary (declared ``const double``) or an output slot."""

    target: str
    code: str
    temporary: bool
    uses: tuple[str, ...] = ()
    #: Work-array slot the value is stored to for a later part (split kernels only).
    slot: int | None = None


@dataclass(frozen=True)
class Part:
    """Consecutive statements of a split kernel and the earlier values they read."""

    loads: tuple[tuple[str, int], ...]
    statements: tuple[Statement, ...]


def on_demand(temporaries: list[Statement], outputs: list[Statement]) -> list[Statement]:
    """Outputs in their order, each preceded by the temporaries it needs that are not yet
    computed (depth first, so every temporary still follows what it uses)."""
    by_name = {t.target: t for t in temporaries}
    done: set[str] = set()
    ordered: list[Statement] = []
    for out in outputs:
        stack = [(name, False) for name in reversed(out.uses) if name in by_name]
        while stack:
            name, expanded = stack.pop()
            if name in done:
                continue
            if expanded:
                done.add(name)
                ordered.append(by_name[name])
                continue
            stack.append((name, True))
            stack.extend((u, False) for u in reversed(by_name[name].uses)
                         if u in by_name and u not in done)
        ordered.append(out)
    return ordered


def split(statements: list[Statement]) -> tuple[list[Part], int]:
    """Cut ``statements`` into parts of :data:`PART`; return them and the work array's
    length. A slot is given back after the last part that reads its value."""
    chunks = [statements[i:i + PART] for i in range(0, len(statements), PART)]
    defined = {s.target: i for i, chunk in enumerate(chunks) for s in chunk if s.temporary}
    last_use: dict[str, int] = {}
    for i, chunk in enumerate(chunks):
        for s in chunk:
            for name in s.uses:
                if defined.get(name, i) != i:
                    last_use[name] = i
    free: list[int] = []
    slots: dict[str, int] = {}
    size = 0
    parts = []
    for i, chunk in enumerate(chunks):
        loads = tuple(sorted({(n, slots[n]) for s in chunk for n in s.uses
                              if defined.get(n, i) != i}, key=lambda ls: ls[1]))
        for name, slot in loads:        # dead after this part: its slot can be reused
            if last_use[name] == i:     # by the values this part stores
                free.append(slot)
        stored = []
        for s in chunk:
            if s.target in last_use:
                if not free:
                    free.append(size)
                    size += 1
                slots[s.target] = free.pop()
                s = Statement(s.target, s.code, s.temporary, s.uses, slots[s.target])
            stored.append(s)
        parts.append(Part(loads, tuple(stored)))
    return parts, size
