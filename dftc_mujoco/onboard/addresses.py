"""Arrays handed to compiled code by address: one (K, 6) table instead of K arguments.

numba unboxes every array argument on every call: it types the array, takes a reference and
allocates a memory record for it, about 75 ns each. The period's records held 48 arrays
(50 since 2026-12-01): 3.8 µs a call, more than the compiled work of a period at N = 16
(measured with an empty function of the period's arguments). A StructRef or a typed List
of the arrays unboxes in 0.7 or 1.0 µs, but building one costs 0.41 or 0.50-0.58 s in every
process, even from numba's cache.

:func:`address_table` writes each array's address, dtype number, ndim and shape in one row
of an int64 table; the compiled side rebuilds the arrays as views (:func:`view1`,
:func:`view2`, :func:`view3`: about 5 ns each) and checks each row's dtype and ndim against
what it reads there, so a table that does not match its reader raises instead of reading
wrong memory. The views do not own their memory: **the caller keeps the arrays alive as
long as the table** (:class:`Tables` keeps them in the same entry), and they must not be
returned or stored by compiled code.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic
from numba.np.numpy_support import as_dtype

ADDRESS, DTYPE, NDIM, SHAPE = 0, 1, 2, 3  # the table's columns; SHAPE .. SHAPE + 2: the shape


def address_table(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """(K, 6) int64: row k is ``arrays[k]``'s address, ``dtype.num``, ndim and shape (padded
    with 0). Each array must be C-contiguous, aligned and of at most 3 dimensions."""
    table = np.zeros((len(arrays), SHAPE + 3), np.int64)
    for k, a in enumerate(arrays):
        if not (a.flags.c_contiguous and a.flags.aligned) or a.ndim > 3:
            raise ValueError(
                f"array {k} of the table ({a.dtype}, shape {a.shape}): expected a C-contiguous,"
                " aligned array of at most 3 dimensions"
            )
        table[k, :SHAPE] = a.__array_interface__["data"][0], a.dtype.num, a.ndim
        table[k, SHAPE : SHAPE + a.ndim] = a.shape
    return table


class Tables(dict):
    """Tables kept with the arrays they point into, by the caller's key. A copy is empty: a
    copied table would still point into the original's arrays (``copy.deepcopy`` of a team
    copies its arrays but not the addresses written in its tables), and pickling keeps none."""

    def __deepcopy__(self, memo: dict[int, Any]) -> Tables:
        return Tables()

    def __copy__(self) -> Tables:
        return Tables()

    def __reduce__(self) -> tuple[Any, ...]:
        return (Tables, ())


class OwnTable:
    """An object that hands some of its own arrays to compiled code by address: the table is
    :attr:`own_table` (built by :meth:`build_own_table` from :meth:`own_arrays`, which a class
    defines), and a copy or a pickle leaves it out and builds its own (a copied table would
    still point into the original's arrays)."""

    own_table: np.ndarray

    def own_arrays(self) -> list[np.ndarray]:  # pragma: no cover - every user defines it
        raise NotImplementedError

    def build_own_table(self) -> None:
        """(Re)build :attr:`own_table` from :meth:`own_arrays`."""
        self.own_table = address_table(self.own_arrays())

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("own_table", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.build_own_table()


@intrinsic
def _pointer(typingctx, address, dtype):  # pragma: no cover - compiled
    """The integer ``address`` as a pointer to ``dtype`` (a NumPy scalar type, or an array's
    ``dtype`` inside compiled code)."""
    kind = dtype.dtype if isinstance(dtype, types.DType) else dtype.instance_type
    sig = types.CPointer(kind)(types.int64, dtype)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@intrinsic
def _number(typingctx, dtype):  # pragma: no cover - compiled
    """``np.dtype(dtype).num``, a constant of the compiled code."""
    num = as_dtype(dtype.instance_type).num

    def codegen(context, builder, signature, args):
        return context.get_constant(types.int64, num)

    return types.int64(dtype), codegen


@njit(inline="always")
def _checked(table, k, dtype, ndim):  # pragma: no cover - compiled
    if table[k, DTYPE] != _number(dtype) or table[k, NDIM] != ndim:
        raise TypeError("an address table's row does not hold the array its reader expects")
    return _pointer(table[k, ADDRESS], dtype)


@njit(inline="always")
def view1(table, k, dtype):  # pragma: no cover - compiled
    """Row ``k`` of ``table`` as a 1-D array of ``dtype`` (a view: see the module)."""
    return carray(_checked(table, k, dtype, 1), (table[k, SHAPE],))


@njit(inline="always")
def view2(table, k, dtype):  # pragma: no cover - compiled
    """Row ``k`` of ``table`` as a 2-D array of ``dtype`` (a view: see the module)."""
    return carray(_checked(table, k, dtype, 2), (table[k, SHAPE], table[k, SHAPE + 1]))


@njit(inline="always")
def view3(table, k, dtype):  # pragma: no cover - compiled
    """Row ``k`` of ``table`` as a 3-D array of ``dtype`` (a view: see the module)."""
    shape = (table[k, SHAPE], table[k, SHAPE + 1], table[k, SHAPE + 2])
    return carray(_checked(table, k, dtype, 3), shape)


@njit(inline="always")
def at1(address, size, dtype):  # pragma: no cover - compiled
    """The 1-D array of ``size`` ``dtype`` at ``address`` (a view: see the module)."""
    return carray(_pointer(address, dtype), (size,))


@njit(inline="always")
def at2(address, rows, cols, dtype):  # pragma: no cover - compiled
    """The 2-D array of ``rows`` × ``cols`` ``dtype`` at ``address`` (a view: see the module)."""
    return carray(_pointer(address, dtype), (rows, cols))
