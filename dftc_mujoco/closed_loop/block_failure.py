"""Which onboard block an exception came from, said in one line.

A block is found by the frames the exception went through (their ``self``), so a
plug-in's own exception is named by its block and class, whatever it is. During the
run that ends the run and keeps its records (:class:`~.errors.BlockError`); before it
(a block's thresholds at t = 0, its settle time) it is bad input and nothing runs.
"""

from __future__ import annotations

from ..errors import BlockError, InputError, raised_line
from ..onboard.block import BadOutput, Block


def _raising_block(exc: BaseException) -> Block | None:
    """The innermost onboard block an exception came through (by its frames' ``self``)."""
    if isinstance(exc, BadOutput):  # the block that returned it
        return exc.block
    found = None
    tb = exc.__traceback__
    while tb is not None:
        me = tb.tb_frame.f_locals.get("self")
        if isinstance(me, Block):
            found = me
        tb = tb.tb_next
    return found


def _raised(block: Block | None, exc: BaseException) -> str:
    """What ``block`` (None: unknown) raised, in words: ``onboard block K (module:Class)
    raised E: the first line of its message`` (for a BadOutput, ``... returned from
    its method shape (..), expected (..),``)."""
    where = (
        f"onboard block {block.kind} ({type(block).__module__}:{type(block).__qualname__})"
        if block is not None
        else "the team's step"
    )
    if isinstance(exc, BadOutput):
        return f"{where} {exc}"
    return f"{where} raised {raised_line(exc)}"


def block_error(exc: BaseException, t: float) -> BlockError:
    """One line for an exception raised inside the team's step: the innermost onboard
    block it came from, the exception and the time."""
    return BlockError(
        f"{_raised(_raising_block(exc), exc)} at t = {t:.2f} s; "
        "the run stopped there and its records are kept"
    )


def setup_error(exc: Exception, source: str) -> InputError | None:
    """One line for an exception an onboard block raised while the team was being set up
    (its thresholds at t = 0, its settle time...); None when no block raised it (a bug
    of the simulator's own: its traceback is the report)."""
    block = _raising_block(exc)
    if block is None:
        return None
    return InputError(
        f"{source}: {_raised(block, exc)} while the team was being set up; nothing ran"
    )
