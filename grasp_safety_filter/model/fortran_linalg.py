"""scipy's BLAS and LAPACK, called from compiled kernels by symbol name (cacheable).

scipy exports its BLAS and LAPACK as a public Cython API (``scipy.linalg.cython_blas``,
``scipy.linalg.cython_lapack``). Each routine's address is registered with LLVM under a
name of this package's own (``llvmlite.binding.add_symbol``) when this module is imported,
and the kernels declare the routine by that name, so their cached machine code refers to a
name, not to one process's address, and a later process links it to its own scipy.

The routines follow Fortran's conventions: matrices column-major, every argument by
pointer. Here a character, integer or float argument is passed by value and put on the
stack by the call; an array argument is an array and an offset (in entries) into it, the
routine's matrix or vector starting there.

:func:`dot` and :func:`matrix_vector` are numpy's ``@`` of a vector, or a row-major matrix,
by a contiguous vector, and :func:`matrix_matrix` of two C-ordered matrices: they make the
BLAS call numpy makes for those shapes and strides (or its plain loop for a single row or
column), so a kernel built from them gives numpy's results bit for bit where both
libraries' routines round alike (tested for each shape used).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from llvmlite import binding, ir
from numba import types
from numba.core import cgutils
from numba.extending import get_cython_function_address, intrinsic
import numpy as np

from grasp_safety_filter.model.compiled import kernel

_PREFIX = 'grasp_safety_filter_scipy_'


def _routine(module: str, name: str, kinds: str, returns_double: bool = False) -> Callable:
    """Return a kernel-callable intrinsic for scipy's ``name`` from ``module``.

    Args:
        module: ``'blas'`` or ``'lapack'``.
        name: The routine, e.g. ``'dgemv'``.
        kinds: One letter per Fortran argument: ``c`` a character (its code), ``i`` an
            integer, ``d`` a float, ``a`` a float64 array and an offset, ``n`` an int32
            array and an offset (the last two take two arguments of the call).
        returns_double: The routine is a function returning a float (``ddot``).
    """
    symbol = _PREFIX + name
    binding.add_symbol(symbol, get_cython_function_address(f'scipy.linalg.cython_{module}', name))
    scalar_types = {'c': ir.IntType(8), 'i': ir.IntType(32), 'd': ir.DoubleType()}
    pointer_types = {
        'c': ir.IntType(8).as_pointer(),
        'i': ir.IntType(32).as_pointer(),
        'd': ir.DoubleType().as_pointer(),
        'a': ir.DoubleType().as_pointer(),
        'n': ir.IntType(32).as_pointer(),
    }
    return_type = types.float64 if returns_double else types.void

    @intrinsic
    def call(typingctx: Any, *arguments: types.Type) -> tuple[Any, Callable]:
        # numba passes the arguments of a star-parameter as one tuple.
        signature = return_type(types.StarArgTuple.from_types(arguments))

        def codegen(context: Any, builder: ir.IRBuilder, sig: Any, packed: list) -> Any:
            args = cgutils.unpack_tuple(builder, packed[0])
            sig = return_type(*sig.args[0].types)
            pointers = []
            position = 0
            for kind in kinds:
                value, value_type = args[position], sig.args[position]
                if kind in 'an':
                    array = context.make_array(value_type)(context, builder, value)
                    offset = context.cast(
                        builder, args[position + 1], sig.args[position + 1], types.intp
                    )
                    pointers.append(builder.gep(array.data, [offset]))
                    position += 2
                    continue
                target = {'c': types.uint8, 'i': types.int32, 'd': types.float64}[kind]
                cast = context.cast(builder, value, value_type, target)
                slot = cgutils.alloca_once(builder, scalar_types[kind])
                builder.store(cast, slot)
                pointers.append(slot)
                position += 1
            function_type = ir.FunctionType(
                ir.DoubleType() if returns_double else ir.VoidType(),
                [pointer_types[kind] for kind in kinds],
            )
            function = cgutils.get_or_insert_function(builder.module, function_type, symbol)
            result = builder.call(function, pointers)
            return result if returns_double else context.get_dummy_value()

        return signature, codegen

    return call


#: ``ddot(n, x, incx, y, incy)``.
ddot = _routine('blas', 'ddot', 'iaiai', returns_double=True)
#: ``dgemm(transa, transb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc)``.
dgemm = _routine('blas', 'dgemm', 'cciiidaiaidai')
#: ``dgemv(trans, m, n, alpha, a, lda, x, incx, beta, y, incy)``.
dgemv = _routine('blas', 'dgemv', 'ciidaiaidai')
#: ``dgesv(n, nrhs, a, lda, ipiv, b, ldb, info)``: scipy's, as numba's ``np.linalg.solve``.
dgesv = _routine('lapack', 'dgesv', 'iiainain')
#: ``dgeqrf(m, n, a, lda, tau, work, lwork, info)``.
dgeqrf = _routine('lapack', 'dgeqrf', 'iiaiaain')
#: ``dgeqp3(m, n, a, lda, jpvt, tau, work, lwork, info)``.
dgeqp3 = _routine('lapack', 'dgeqp3', 'iiainaain')
#: ``dpotrf(uplo, n, a, lda, info)``.
dpotrf = _routine('lapack', 'dpotrf', 'ciain')
#: ``dorgqr(m, n, k, a, lda, tau, work, lwork, info)``.
dorgqr = _routine('lapack', 'dorgqr', 'iiiaiaain')
#: ``dtrtrs(uplo, trans, diag, n, nrhs, a, lda, b, ldb, info)``.
dtrtrs = _routine('lapack', 'dtrtrs', 'ccciiaiain')


@intrinsic
def fused_multiply_add(
    typingctx: Any, a: types.Type, b: types.Type, c: types.Type
) -> tuple[Any, Callable]:
    """Return ``a b + c`` rounded once (LLVM's ``fma``), for float64 a, b, c."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: list) -> Any:
        return builder.fma(*args)

    return signature, codegen


@kernel
def _strided_ddot(n: int, x: np.ndarray, x_offset: int, x_step: int, y: np.ndarray) -> float:
    """Return numpy's BLAS's ``ddot`` for a strided x (OpenBLAS 0.3.31, x86-64).

    Its strided loop sums in an order scipy's build (0.3.30) rounds differently, by one
    fused multiply-add per group of four.
    """
    first = 0.0
    second = 0.0
    i = 0
    while i < n & -4:
        p1 = y[i] * x[x_offset + i * x_step]
        p2 = y[i + 1] * x[x_offset + (i + 1) * x_step]
        p3 = y[i + 2] * x[x_offset + (i + 2) * x_step]
        p4 = y[i + 3] * x[x_offset + (i + 3) * x_step]
        first += p1 + p3
        second += p2 + p4
        i += 4
    while i < n:
        first = fused_multiply_add(y[i], x[x_offset + i * x_step], first)
        i += 1
    return first + second


@kernel
def dot(n: int, x: np.ndarray, x_offset: int, x_step: int, y: np.ndarray, y_offset: int) -> float:
    """Return numpy's ``x @ y`` of n entries: x from ``x_offset`` every ``x_step``, y contiguous.

    numpy adds BLAS's sum to a zero (so a sum of -0 is +0).
    """
    if n == 0:
        return 0.0
    if x_step != 1:
        return 0.0 + _strided_ddot(n, x, x_offset, x_step, y[y_offset:])
    return 0.0 + ddot(n, x, x_offset, 1, y, y_offset, 1)


@kernel
def matrix_vector(
    rows: int,
    columns: int,
    A: np.ndarray,
    A_offset: int,
    row_step: int,
    column_step: int,
    x: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write numpy's ``M @ x[:columns]`` into ``out[:rows]``, for M (rows, columns) in A.

    ``M[i, j] = A[A_offset + i row_step + j column_step]``, one of the steps 1 and the
    other at least the extent it steps over (a C-ordered matrix or its transpose).
    """
    if rows == 0:
        return
    if columns == 0:
        out[:rows] = 0.0
    elif rows == 1:
        out[0] = dot(columns, A, A_offset, column_step, x, 0)
    elif columns == 1:
        # numpy's own loop: a zero plus each product.
        for i in range(rows):
            out[i] = 0.0 + A[A_offset + i * row_step] * x[0]
    elif column_step == 1:
        # numpy: a column-major (columns, rows) matrix, transposed.
        dgemv(ord('T'), columns, rows, 1.0, A, A_offset, row_step, x, 0, 1, 0.0, out, 0, 1)
    else:
        # numpy: a row-major (columns, rows) matrix, transposed; BLAS: column-major, not.
        dgemv(ord('N'), rows, columns, 1.0, A, A_offset, column_step, x, 0, 1, 0.0, out, 0, 1)


@kernel
def matrix_matrix(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """Write numpy's ``A @ B`` into ``out``: C-ordered (p, q) by (q, r), p and r at least 2.

    numpy's row-major ``dgemm`` is BLAS's column-major one on the transposes:
    ``out^T = B^T A^T``.
    """
    p, q = A.shape
    r = B.shape[1]
    dgemm(ord('N'), ord('N'), r, p, q, 1.0, B, 0, r, A, 0, q, 0.0, out, 0, r)
