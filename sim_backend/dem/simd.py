"""Four-lane float64 vectors for the compiled kernel: a numba type held in one SIMD register.

numba vectorises a loop only when LLVM can prove that its arrays do not overlap; the kernel's
loops touch five or six arrays each over a handful of lanes, so LLVM either gives up or spends
more on its run-time overlap checks than on the arithmetic. :data:`vec4` makes the lanes explicit
instead: a value of this type is an LLVM ``<4 x double>``, so a sum carried over a loop stays in a
register, and every load, store and operation below is one vector instruction (AVX2 and up;
two SSE2 instructions elsewhere).

Operations (all elementwise, in numba-compiled code only)::

    v = vload(a, i)          # a[i : i + 4] of a C-contiguous 1-D float64 array (no bounds check)
    vstore(a, i, v)          # a[i : i + 4] = v
    v = vsplat(x)            # (x, x, x, x)
    v = vbcast(a, i)         # (a[i],) * 4 of a C-contiguous 1-D float64 array (no bounds check,
                             # no negative index: one broadcast load)
    v + w, v - w, v * w      # also with a float on either side
    vfma(a, b, c)            # a * b + c, one rounding
    vmax(v, w), vsqrt(v)
    x = vlane(v, j)          # lane j as a float

Plain ``+ - *`` are IEEE operations that LLVM may not fuse, so the same source gives the same
bits in every lane whatever the lane's position or the batch around it.
"""

from __future__ import annotations

import operator
from typing import TYPE_CHECKING, Any

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic, models, overload, register_model

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

__all__ = [
    "LANES",
    "Vec4",
    "vbcast",
    "vec4",
    "vfma",
    "vlane",
    "vload",
    "vmax",
    "vsplat",
    "vsqrt",
    "vstore",
]

#: lanes of one vector
LANES = 4
_VT = ir.VectorType(ir.DoubleType(), LANES)
_I32 = ir.IntType(32)


class Vec4Type(types.Type):
    """numba type of four float64 lanes held as one LLVM ``<4 x double>``."""

    def __init__(self) -> None:
        super().__init__(name="vec4")


vec4 = Vec4Type()


@register_model(Vec4Type)
class _Vec4Model(models.PrimitiveModel):
    def __init__(self, dmm: Any, fe_type: Any) -> None:
        super().__init__(dmm, fe_type, _VT)


def _llvm_fn(builder: ir.IRBuilder, name: str, n_args: int) -> ir.Function:
    fnty = ir.FunctionType(_VT, [_VT] * n_args)
    return cgutils.get_or_insert_function(builder.module, fnty, f"llvm.{name}.v4f64")


def _check_array(arr: Any, idx: Any) -> None:
    ok = (
        isinstance(arr, types.Array)
        and arr.dtype == types.float64
        and arr.ndim == 1
        and arr.layout == "C"
        and isinstance(idx, types.Integer)
    )
    if not ok:
        raise TypingError(
            f"vload/vstore take a C-contiguous 1-D float64 array and an int, not {arr}"
        )


def _element_ptr(context: Any, builder: ir.IRBuilder, aryty: Any, ary: Any, idx: Any) -> Any:
    data = context.make_array(aryty)(context, builder, ary).data
    return builder.gep(data, [idx], inbounds=True)


def _lane_ptr(context: Any, builder: ir.IRBuilder, aryty: Any, ary: Any, idx: Any) -> Any:
    return builder.bitcast(_element_ptr(context, builder, aryty, ary, idx), _VT.as_pointer())


def _splat(builder: ir.IRBuilder, x: Any) -> Any:
    """The double ``x`` in every lane."""
    v = builder.insert_element(ir.Constant(_VT, ir.Undefined), x, ir.Constant(_I32, 0))
    zeros = ir.Constant(ir.VectorType(_I32, LANES), [0] * LANES)
    return builder.shuffle_vector(v, v, zeros)


@intrinsic
def _vload(typingctx: Any, arr: Any, idx: Any) -> Any:
    """``arr[idx : idx + 4]`` as a vector."""
    _check_array(arr, idx)

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return builder.load(_lane_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)

    return vec4(arr, idx), codegen


@intrinsic
def _vstore(typingctx: Any, arr: Any, idx: Any, val: Any) -> Any:
    """``arr[idx : idx + 4] = val``."""
    _check_array(arr, idx)
    if not isinstance(val, Vec4Type):
        raise TypingError(f"vstore stores a vec4, got {val}")

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        builder.store(args[2], _lane_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
        return context.get_dummy_value()

    return types.none(arr, idx, val), codegen


@intrinsic
def _vbcast(typingctx: Any, arr: Any, idx: Any) -> Any:
    """``(arr[idx],) * 4``: one broadcast load, without numba's handling of a negative index."""
    _check_array(arr, idx)

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        ptr = _element_ptr(context, builder, sig.args[0], args[0], args[1])
        return _splat(builder, builder.load(ptr, align=8))

    return vec4(arr, idx), codegen


@intrinsic
def _vsplat(typingctx: Any, x: Any) -> Any:
    """``(x, x, x, x)``."""
    if not isinstance(x, (types.Float, types.Integer)):
        raise TypingError(f"vsplat takes a number, got {x}")

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return _splat(builder, context.cast(builder, args[0], sig.args[0], types.float64))

    return vec4(x), codegen


@intrinsic
def _vlane(typingctx: Any, v: Any, j: Any) -> Any:
    """Lane ``j`` of ``v`` as a float."""

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return builder.extract_element(args[0], builder.trunc(args[1], _I32))

    return types.float64(vec4, j), codegen


@intrinsic
def _vfma(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    """``a * b + c`` with one rounding."""

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return builder.call(_llvm_fn(builder, "fma", 3), list(args))

    return vec4(vec4, vec4, vec4), codegen


@intrinsic
def _vsqrt(typingctx: Any, a: Any) -> Any:
    """Square root of every lane."""

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return builder.call(_llvm_fn(builder, "sqrt", 1), list(args))

    return vec4(vec4), codegen


@intrinsic
def _vmax(typingctx: Any, a: Any, b: Any) -> Any:
    """Lane-wise maximum (``maxnum``: a NaN lane gives the other operand)."""

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
        return builder.call(_llvm_fn(builder, "maxnum", 2), list(args))

    return vec4(vec4, vec4), codegen


def _binary(op_name: str) -> Any:
    @intrinsic
    def vop(typingctx: Any, a: Any, b: Any) -> Any:
        def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> Any:
            return getattr(builder, op_name)(args[0], args[1])

        return vec4(vec4, vec4), codegen

    return vop


def _overload_operator(op: Any, vop: Any) -> None:
    number = (types.Float, types.Integer)

    def both(a: Any, b: Any) -> Any:
        return vop(a, b)

    def right_number(a: Any, b: Any) -> Any:
        return vop(a, vsplat(b))

    def left_number(a: Any, b: Any) -> Any:
        return vop(vsplat(a), b)

    def typer(a: Any, b: Any) -> Any:
        a_vec, b_vec = isinstance(a, Vec4Type), isinstance(b, Vec4Type)
        if a_vec and b_vec:
            return both
        if a_vec and isinstance(b, number):
            return right_number
        if b_vec and isinstance(a, number):
            return left_number
        return None

    overload(op)(typer)


for _op, _name in ((operator.add, "fadd"), (operator.sub, "fsub"), (operator.mul, "fmul")):
    _overload_operator(_op, _binary(_name))


if TYPE_CHECKING:  # what the kernel's annotations and mypy see

    class Vec4:
        """Four float64 lanes (compiled code only)."""

        def __add__(self, other: Vec4 | float) -> Vec4: ...
        def __radd__(self, other: float) -> Vec4: ...
        def __sub__(self, other: Vec4 | float) -> Vec4: ...
        def __rsub__(self, other: float) -> Vec4: ...
        def __mul__(self, other: Vec4 | float) -> Vec4: ...
        def __rmul__(self, other: float) -> Vec4: ...

    def vload(arr: NDArray[np.float64], idx: int) -> Vec4: ...
    def vstore(arr: NDArray[np.float64], idx: int, val: Vec4) -> None: ...
    def vsplat(x: float) -> Vec4: ...
    def vbcast(arr: NDArray[np.float64], idx: int) -> Vec4: ...
    def vlane(v: Vec4, j: int) -> float: ...
    def vfma(a: Vec4, b: Vec4, c: Vec4) -> Vec4: ...
    def vsqrt(a: Vec4) -> Vec4: ...
    def vmax(a: Vec4, b: Vec4) -> Vec4: ...

else:
    Vec4 = Vec4Type
    vload, vstore, vsplat, vbcast, vlane = _vload, _vstore, _vsplat, _vbcast, _vlane
    vfma, vsqrt, vmax = _vfma, _vsqrt, _vmax
