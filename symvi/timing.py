"""Time limits and progress lines for long symbolic work (builds, derivation checks).

SymPy cannot be asked to stop, but pure-Python work can be interrupted: ``SIGALRM``
(``setitimer``) raises :class:`Expired` in the main thread at the deadline, repeated
every :data:`REPEAT` seconds in case the code catches the first one. Python allows
signal handlers in the main thread only; elsewhere the work runs to its end. So does it
while another timer is pending (a caller's alarm, pytest-timeout's): that timer and its
handler are left alone, to fire when their owner asked.
"""
from __future__ import annotations

import contextlib
import signal
import threading
import time
from typing import Callable, Iterator

#: Once the deadline has passed, SIGALRM is repeated this often (seconds).
REPEAT = 0.1
#: The longest delay armed (seconds): a year.
MAXIMUM = 3.2e7


class Expired(BaseException):
    """Raised inside interrupted work at its deadline. A BaseException so that the work's
    own ``except Exception`` clauses (SymPy has many) do not swallow it."""


def interruptible() -> bool:
    """Whether :func:`interrupted_after` can interrupt work here: the main thread, on Unix,
    with no other timer pending."""
    return (hasattr(signal, "setitimer")
            and threading.current_thread() is threading.main_thread()
            and signal.getitimer(signal.ITIMER_REAL)[0] == 0.0)


#: Code run while a ``with`` block is left: an alarm there is put off to the next repeat.
_EXITS = frozenset({contextlib._GeneratorContextManager.__exit__.__code__})


def _leaving_context(frame) -> bool:
    """Whether ``frame`` or a caller of it is a generator context manager's ``__exit__``."""
    while frame is not None:
        if frame.f_code in _EXITS:
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def interrupted_after(seconds: float | None) -> Iterator[None]:
    """Raise :class:`Expired` in the body once ``seconds`` have passed (None: never), where
    :func:`interruptible`; elsewhere the body runs to its end."""
    if seconds is None or not interruptible():
        yield
        return
    armed = [True]

    def on_alarm(signum, frame) -> None:
        # not once the body has ended and the timer is being disarmed, nor while a
        # context manager is being left (an alarm repeated during the unwinding of the
        # first Expired would stop contextlib before it closes this generator, leaving
        # the timer running; the next repeat raises once the exits are done)
        if armed[0] and not _leaving_context(frame):
            raise Expired()

    saved_handler = signal.signal(signal.SIGALRM, on_alarm)
    try:
        # a year at most: setitimer overflows time_t on larger delays
        signal.setitimer(signal.ITIMER_REAL, min(max(seconds, 1e-3), MAXIMUM), REPEAT)
        yield
    finally:
        try:
            armed[0] = False
        finally:   # runs even if the alarm fired just before the line above
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, saved_handler if saved_handler is not None
                          else signal.SIG_DFL)


@contextlib.contextmanager
def announced(label: str, say: Callable[[str], None] | None, slow: float,
              verbose: bool = False) -> Iterator[None]:
    """Tell ``say`` when the body has run for ``slow`` seconds and, then (or always when
    ``verbose``), how long it took; nothing without ``say``."""
    began = time.monotonic()
    if say is None:
        yield
        return
    announce = threading.Timer(slow, say, [f"{label} is running (over {slow:g} s so far) ..."])
    announce.daemon = True
    announce.start()
    try:
        yield
    finally:
        announce.cancel()
        elapsed = time.monotonic() - began
        if verbose or elapsed >= slow:
            say(f"{label} took {elapsed:.2f} s")
