"""A helper thread that stays in compiled code between the passes it takes.

A helper of the thread pool (:mod:`.sharing`) returns to Python after its rows and waits
for the next ones asleep; to begin them it must wake and take Python's lock, which the
calling thread holds until its commands' compiled call. At N = 1000 that made a helper begin
its rows 0.11-0.2 ms after they were handed over, and the caller join it 0.2-0.36 ms after
both had ended, each period (2026-12-01, ``benchmarks/bench_pass.py``). A *resident* helper
never leaves its compiled loop while passes come: it watches a mailbox (an int64 array) with
atomic loads, rebuilds the period's records from the addresses posted there (the team's
:func:`~.period.unpack` table), runs its rows (:func:`~.period.shared_rows`, the very code the
caller runs) and posts back how many flags it raised and when it began and ended, by the
processor's time-stamp counter. The caller waits for that answer in compiled code too.
Between passes the helper checks the mailbox, pausing the processor and yielding it to any
other thread that wants it (``sched_yield``); after :data:`PATIENCE` without a pass, or
once it finds it was kept off the processor (:data:`PREEMPTED`: another thread wants it), it
goes back to Python and sleeps until the next pass wakes it.

It is built on x86-64 Linux only (:func:`available`): the time-stamp counter, the ``pause``
instruction and the system call are that platform's; elsewhere the pool's helpers run the
pass. The numbers are the same either way: each row is computed by the same code from the
same arrays, whoever runs it.
"""

from __future__ import annotations

import atexit
import functools
import platform
import sys
import threading
import time

import llvmlite.binding
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .addresses import at1, at2
from .period import shared_rows

# the mailbox: what the caller posts (its own cache lines) ...
SEQ, TABLE, TABLE_ROWS, MU, MU_ROWS, MU_COLS = 0, 1, 2, 3, 4, 5
TIMER, TIMER_ROWS, TIMER_COLS, NUMBERS, NUMBERS_SIZE, FLAGS, LO, HI, SCRATCH = range(6, 15)
# ... and what the helper answers, 128 bytes further
DONE, COUNT, BEGAN, ENDED, STATE = 16, 17, 18, 19, 20
MAILBOX = 24
ASLEEP, WATCHING, FAILED = 0, 1, 2  # the helper's STATE
STOP = -1  # a SEQ that ends the helper's loop

#: [s] how long a helper watches the mailbox without a pass before it goes back to sleep
PATIENCE = 0.05
#: [s] how long it only pauses between two looks before it also yields the processor
YIELD_AFTER = 2e-5
#: [s] two looks at the mailbox this far apart mean the processor ran another thread
#: meanwhile: the helper sleeps rather than take the processor from it (two campaign workers
#: on two cores, N = 400: helpers that kept watching made each run 10-20 % slower)
PREEMPTED = 2e-4
#: [s] how long the caller waits for a helper's rows before it gives up on the helper
GIVE_UP = 30.0

FDIR, ROUND_NOW, ESTIMATES, NORMS, STREAM = 1, 2, 4, 8, 16  # FLAGS' bits (PeriodInputs)


@functools.cache
def available() -> bool:
    """Whether resident helpers run here (x86-64 Linux)."""
    return sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")


if available():  # the system call below is inline assembly, which LLVM must parse
    llvmlite.binding.initialize_native_asmparser()


@intrinsic
def ticks(typingctx):
    """The processor's time-stamp counter (``rdtsc``)."""

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])

    return types.int64(), codegen


@intrinsic
def _pause(typingctx):
    """x86's ``pause``: a spinning loop lets the core's other work and the memory go first."""

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.VoidType(), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse2.pause")
        builder.call(fn, [])
        return context.get_dummy_value()

    return types.void(), codegen


@intrinsic
def _yield(typingctx):
    """Linux's ``sched_yield`` (system call 24 on x86-64): any other runnable thread of this
    processor runs first. Written as the system call itself, not through libc, so that the
    compiled loop stays in numba's cache."""

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(i64, [i64])
        asm = builder.asm(fnty, "syscall", "={rax},0,~{rcx},~{r11},~{memory}", [i64(24)], True)
        del asm
        return context.get_dummy_value()

    return types.void(), codegen


@intrinsic
def load(typingctx, array, index):
    """``array[index]`` of an int64 array, read atomically (sequentially consistent)."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        arr_t, idx_t = signature.args
        arr = context.make_array(arr_t)(context, builder, args[0])
        idx = context.cast(builder, args[1], idx_t, types.intp)
        ptr = cgutils.get_item_pointer(context, builder, arr_t, arr, [idx], wraparound=False)
        return builder.load_atomic(ptr, "seq_cst", 8)

    return types.int64(array, index), codegen


@intrinsic
def store(typingctx, array, index, value):
    """``array[index] = value`` into an int64 array, written atomically (sequentially
    consistent: every store before it is seen before it)."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        arr_t, idx_t, val_t = signature.args
        arr = context.make_array(arr_t)(context, builder, args[0])
        idx = context.cast(builder, args[1], idx_t, types.intp)
        val = context.cast(builder, args[2], val_t, types.int64)
        ptr = cgutils.get_item_pointer(context, builder, arr_t, arr, [idx], wraparound=False)
        builder.store_atomic(val, ptr, "seq_cst", 8)
        return context.get_dummy_value()

    return types.void(array, index, value), codegen


@njit(cache=True, nogil=True)
def put(mail, index, value):  # pragma: no cover - compiled
    """:func:`store` for Python's side."""
    store(mail, index, value)


@njit(cache=True, nogil=True)
def now():  # pragma: no cover - compiled
    """The time-stamp counter, for the caller's own timings."""
    return ticks()


@njit(cache=True, nogil=True)
def serve(mail, like, patience, patient, preempted):  # pragma: no cover - compiled
    """The helper's loop: each pass posted in ``mail`` (a new SEQ) run and answered, until
    ``patience`` ticks pass without one, two looks at the mailbox lie more than
    ``preempted`` ticks apart (the processor went to another thread: it is wanted), or SEQ
    is :data:`STOP`; ``like`` is an empty array of the decision's timer type; the loop only
    pauses for ``patient`` ticks after a pass, then yields the processor at each look too."""
    done = load(mail, DONE)
    store(mail, STATE, WATCHING)
    last = ticks()
    look = last
    while True:
        seq = load(mail, SEQ)
        if seq == STOP:
            store(mail, STATE, ASLEEP)
            return
        if seq == done:
            t = ticks()
            waited, gap, look = t - last, t - look, t
            if waited > patience or gap > preempted:
                store(mail, STATE, ASLEEP)
                if load(mail, SEQ) == done:  # a pass posted now sees ASLEEP and wakes us
                    return
                store(mail, STATE, WATCHING)
            elif waited > patient:
                _yield()
            else:
                _pause()
            continue
        began = ticks()
        table = at2(mail[TABLE], mail[TABLE_ROWS], 6, np.int64)
        mu = at2(mail[MU], mail[MU_ROWS], mail[MU_COLS], np.float64)
        timer = at2(mail[TIMER], mail[TIMER_ROWS], mail[TIMER_COLS], like.dtype)
        numbers = at1(mail[NUMBERS], mail[NUMBERS_SIZE], np.float64)
        f = mail[FLAGS]
        count = shared_rows(
            (f & FDIR) != 0, (f & ROUND_NOW) != 0, (f & ESTIMATES) != 0, (f & NORMS) != 0,
            (f & STREAM) != 0, table, mu, timer, numbers, mail[LO], mail[HI], mail[SCRATCH],
        )  # fmt: skip
        mail[COUNT] = count
        mail[BEGAN] = began
        mail[ENDED] = ticks()
        store(mail, DONE, seq)  # after the rows and the answers above
        done = seq
        last = ticks()
        look = last


@njit(cache=True, nogil=True)
def post(mail, table, mu, timer, numbers, flags, lo, hi, b, seq):  # pragma: no cover
    """Hand robots ``lo`` .. ``hi - 1`` (scratch row ``b``) of the pass described by the
    address ``table``, ``mu``, ``timer``, ``numbers`` (:func:`~.period.unpack`) and
    ``flags`` to the helper of ``mail`` as pass ``seq``; returns the helper's state, read
    after the post (ASLEEP: it must be woken)."""
    mail[TABLE], mail[TABLE_ROWS] = table.ctypes.data, table.shape[0]
    mail[MU], mail[MU_ROWS], mail[MU_COLS] = mu.ctypes.data, mu.shape[0], mu.shape[1]
    mail[TIMER], mail[TIMER_ROWS] = timer.ctypes.data, timer.shape[0]
    mail[TIMER_COLS] = timer.shape[1]
    mail[NUMBERS], mail[NUMBERS_SIZE] = numbers.ctypes.data, numbers.shape[0]
    mail[FLAGS], mail[LO], mail[HI], mail[SCRATCH] = flags, lo, hi, b
    store(mail, SEQ, seq)
    return load(mail, STATE)


@njit(cache=True, nogil=True)
def wait(mail, seq, limit, patient):  # pragma: no cover - compiled
    """Wait until the helper of ``mail`` answered pass ``seq``; returns the ticks then, or
    -1 if the helper failed, -2 after ``limit`` ticks without an answer. It holds no lock
    on Python, so that a helper still asleep can take it to wake, and after ``patient``
    ticks it yields the processor at each look: the helper may be waiting for it."""
    start = ticks()
    while load(mail, DONE) != seq:
        if load(mail, STATE) == FAILED:
            return -1
        t = ticks()
        if t - start > limit:
            return -2
        if t - start > patient:
            _yield()
        else:
            _pause()
    return ticks()


@functools.cache
def tick_rate() -> float:
    """[ticks/s] of the time-stamp counter, measured once against ``time.perf_counter``."""
    now()  # loaded (numba's cache) before it is timed
    t0, k0 = time.perf_counter(), now()
    time.sleep(0.005)
    t1, k1 = time.perf_counter(), now()
    return (k1 - k0) / (t1 - t0)


class Resident:
    """One resident helper thread and its mailbox. :meth:`start` hands it its rows, :meth:`
    finish` waits for them; one caller at a time (:attr:`lock`)."""

    def __init__(self, like: np.ndarray) -> None:
        self.mail = np.zeros(MAILBOX, np.int64)
        self.lock = threading.Lock()
        self.like = like
        self.seq = 0
        self.error: BaseException | None = None
        rate = tick_rate()
        self._patience, self._patient = int(PATIENCE * rate), int(YIELD_AFTER * rate)
        self._preempted = int(PREEMPTED * rate)
        self._limit = int(GIVE_UP * rate)
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="dftc-resident", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while True:
            self._wake.wait()
            self._wake.clear()
            if self.mail[SEQ] == STOP:
                return
            try:
                serve(self.mail, self.like, self._patience, self._patient, self._preempted)
            except BaseException as exc:  # a table its reader does not expect: the caller raises it
                self.error = exc
                put(self.mail, STATE, FAILED)
                return

    def start(self, args: tuple, lo: int, hi: int, b: int) -> int:
        """Post robots ``lo`` .. ``hi - 1`` of the pass ``args`` (table, mu, timer, numbers,
        flags); returns the ticks at the post."""
        self.seq += 1
        t0 = now()
        table, mu, timer, numbers, flags = args
        if post(self.mail, table, mu, timer, numbers, flags, lo, hi, b, self.seq) == ASLEEP:
            self._wake.set()
        return t0

    def finish(self) -> tuple[int, int, int, int]:
        """Wait for the posted rows: (flags raised, ticks when they began, ended, and when
        the caller saw the answer)."""
        seen = wait(self.mail, self.seq, self._limit, self._patient)
        if seen < 0:
            if self.error is not None:
                raise self.error
            raise RuntimeError(
                f"a resident helper did not answer its rows within {GIVE_UP:g} s"
            )  # pragma: no cover - a helper that hangs
        mail = self.mail
        return int(mail[COUNT]), int(mail[BEGAN]), int(mail[ENDED]), seen

    def close(self) -> None:
        """End the helper's thread."""
        put(self.mail, SEQ, STOP)
        self._wake.set()
        self._thread.join()


_residents: dict[tuple[int, np.dtype], list[Resident]] = {}


def residents(count: int, timer: np.dtype) -> list[Resident] | None:
    """``count`` resident helpers of this process for a decision's ``timer`` type, all
    locked for the caller (release each :attr:`~Resident.lock`), or None where they do not
    run (:func:`available`) or another thread holds one."""
    if not available():
        return None
    key = (count, timer)  # dtypes of one kind hash and compare equal
    crew = _residents.get(key)
    # a helper that failed is replaced at once: its thread may not have ended yet
    if crew is None or not all([r.error is None and r._thread.is_alive() for r in crew]):
        crew = _residents[key] = [Resident(np.zeros((0, 0), timer)) for _ in range(count)]
    taken: list[Resident] = []
    for r in crew:
        if not r.lock.acquire(blocking=False):
            for t in taken:
                t.lock.release()
            return None
        taken.append(r)
    return taken


def close_all() -> None:
    """End this process's resident helpers (the next shared pass starts new ones); run at
    the interpreter's exit too, so that no helper is left in its loop while Python ends."""
    for crew in _residents.values():
        for r in crew:
            if r._thread.is_alive():
                r.close()
    _residents.clear()


atexit.register(close_all)
