"""Forward-mode automatic differentiation for NumPy code: dual arrays.

The refinement stage, output error and the Cramer-Rao bound need exact sensitivities of a
simulated response to the parameters and initial states. The force terms are written once
on plain arrays (``pidyn.systems.terms``); a ``Dual`` carries a value and its derivatives
along ``D`` directions through that same code (NumPy ufuncs dispatch to it), so the batched
integrator returns the exact Jacobian of its own discrete scheme with no second copy of the
equations and no finite-difference step to tune.

``Dual(v, d)``: ``v`` has any shape, ``d`` has shape ``v.shape + (D,)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _e(v: Any) -> np.ndarray:
    """A value broadcast against a derivative array (one trailing axis)."""
    return np.asarray(v)[..., None]


class Dual:
    """An array with first derivatives along ``D`` directions (last axis of ``d``)."""

    __slots__ = ("v", "d")
    __array_priority__ = 1000

    def __init__(self, v: Any, d: np.ndarray) -> None:
        self.v = np.asarray(v, dtype=float)
        self.d = d

    # ------------------------------------------------------------------ basics
    @property
    def shape(self) -> tuple[int, ...]:
        return self.v.shape

    @property
    def ndim(self) -> int:
        return self.v.ndim

    def __len__(self) -> int:
        return len(self.v)

    def __repr__(self) -> str:
        return f"Dual(v={self.v!r}, d.shape={self.d.shape})"

    def __getitem__(self, idx: Any) -> Dual:
        # an integrator indexes at every step: a loop, not any() over a generator
        idx_t = idx if type(idx) is tuple else (idx,)
        for i in idx_t:
            if i is Ellipsis:  # the derivative axis stays last
                return Dual(self.v[idx], self.d[idx_t + (slice(None),)])
        return Dual(self.v[idx], self.d[idx_t])

    def __setitem__(self, idx: Any, value: Any) -> None:
        idx_t = idx if isinstance(idx, tuple) else (idx,)
        didx = idx_t + (slice(None),) if any(i is Ellipsis for i in idx_t) else idx_t
        if isinstance(value, Dual):
            self.v[idx] = value.v
            self.d[didx] = value.d
        else:
            self.v[idx] = value
            self.d[didx] = 0.0

    def copy(self) -> Dual:
        return Dual(self.v.copy(), self.d.copy())

    def clip(self, lo: float | None = None, hi: float | None = None) -> Dual:
        out = self
        if lo is not None:
            out = np.maximum(out, lo)
        if hi is not None:
            out = np.minimum(out, hi)
        return out  # type: ignore[return-value]

    # ------------------------------------------------------------------ arithmetic
    def __add__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            return Dual(self.v + o.v, self.d + o.d)
        v = self.v + o
        if np.shape(v) == self.v.shape:  # a read-only view, as broadcast_to gives, at a tenth of its cost
            d = self.d.view()
            d.flags.writeable = False
            return Dual(v, d)
        return Dual(v, np.broadcast_to(self.d, v.shape + self.d.shape[-1:]))

    __radd__ = __add__

    def __neg__(self) -> Dual:
        return Dual(-self.v, -self.d)

    def __matmul__(self, o: Any) -> Dual:
        return _matmul(self, o)

    def __rmatmul__(self, o: Any) -> Dual:
        return _matmul(o, self)

    def __pos__(self) -> Dual:
        return self

    def __sub__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            return Dual(self.v - o.v, self.d - o.d)
        return self + (-np.asarray(o))

    def __rsub__(self, o: Any) -> Dual:
        return (-self) + o

    def __mul__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            return Dual(self.v * o.v, self.d * _e(o.v) + o.d * _e(self.v))
        o = np.asarray(o)
        return Dual(self.v * o, self.d * _e(o))

    __rmul__ = __mul__

    def __truediv__(self, o: Any) -> Dual:
        if isinstance(o, Dual):
            v = self.v / o.v
            return Dual(v, (self.d - o.d * _e(v)) / _e(o.v))
        o = np.asarray(o)
        return Dual(self.v / o, self.d / _e(o))

    def __rtruediv__(self, o: Any) -> Dual:
        v = np.asarray(o) / self.v
        return Dual(v, -self.d * _e(v / self.v))

    def __pow__(self, o: Any) -> Dual:
        if isinstance(o, Dual):  # a^b = exp(b ln a), a > 0 where b varies
            v = self.v**o.v
            base = np.maximum(self.v, 1e-300)
            return Dual(v, self.d * _e(o.v * self.v ** (o.v - 1)) + o.d * _e(v * np.log(base)))
        o = np.asarray(o, dtype=float)
        if o.ndim == 0 and float(o) == 2.0:
            return Dual(self.v * self.v, self.d * _e(2.0 * self.v))
        return Dual(self.v**o, self.d * _e(o * self.v ** (o - 1)))

    def __rpow__(self, o: Any) -> Dual:
        v = np.asarray(o, dtype=float) ** self.v
        return Dual(v, self.d * _e(v * np.log(o)))

    # comparisons act on values (branches of piecewise formulas)
    def __lt__(self, o: Any) -> np.ndarray:
        return self.v < (o.v if isinstance(o, Dual) else o)

    def __le__(self, o: Any) -> np.ndarray:
        return self.v <= (o.v if isinstance(o, Dual) else o)

    def __gt__(self, o: Any) -> np.ndarray:
        return self.v > (o.v if isinstance(o, Dual) else o)

    def __ge__(self, o: Any) -> np.ndarray:
        return self.v >= (o.v if isinstance(o, Dual) else o)

    # ------------------------------------------------------------------ NumPy protocol
    def __array_ufunc__(self, ufunc: np.ufunc, method: str, *inputs: Any, **kw: Any) -> Any:
        fn = _UFUNCS.get(ufunc)
        if method != "__call__" or kw or fn is None:
            raise TypeError(
                unsupported(f"np.{ufunc.__name__}" + ("" if method == "__call__" else f".{method}"))
            )
        return fn(*inputs)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        fn = _FUNCTIONS.get(func)
        if fn is None:
            raise TypeError(unsupported(f"np.{getattr(func, '__name__', func)}"))
        return fn(*args, **kwargs)


def _lift(x: Any, like: Dual) -> Dual:
    if isinstance(x, Dual):
        return x
    v = np.asarray(x, dtype=float)
    return Dual(v, np.zeros(v.shape + like.d.shape[-1:]))


def _unary(f, df):
    def op(a: Any) -> Any:
        v = f(a.v)
        return Dual(v, a.d * _e(df(a.v, v)))

    return op


def _maximum(a: Any, b: Any) -> Dual:
    like = a if isinstance(a, Dual) else b
    a, b = _lift(a, like), _lift(b, like)
    pick = a.v >= b.v
    v = np.where(pick, a.v, b.v)
    return Dual(v, np.where(_e(pick), a.d, b.d))


def _minimum(a: Any, b: Any) -> Dual:
    like = a if isinstance(a, Dual) else b
    a, b = _lift(a, like), _lift(b, like)
    pick = a.v <= b.v
    return Dual(np.where(pick, a.v, b.v), np.where(_e(pick), a.d, b.d))


def _binary(name: str):
    def op(a: Any, b: Any) -> Any:
        if isinstance(a, Dual):
            return getattr(a, f"__{name}__")(b)
        return getattr(b, f"__r{name}__")(a)

    return op


def _sign(a: Dual) -> np.ndarray:
    return np.sign(a.v)


def _matmul(a: Any, b: Any) -> Dual:
    """A dual array times a plain matrix (a network's layer), or a plain matrix times a dual vector."""
    if isinstance(a, Dual) and not isinstance(b, Dual) and np.ndim(b) == 2:
        return Dual(a.v @ b, np.swapaxes(np.swapaxes(a.d, -1, -2) @ b, -1, -2))
    if isinstance(b, Dual) and not isinstance(a, Dual) and np.ndim(a) == 2 and b.ndim == 1:
        return Dual(a @ b.v, a @ b.d)
    raise TypeError(unsupported("np.matmul of two dual arrays, or of other shapes than (..., n) @ (n, m)"))


_UFUNCS = {
    np.add: _binary("add"),
    np.subtract: _binary("sub"),
    np.multiply: _binary("mul"),
    np.true_divide: _binary("truediv"),
    np.power: _binary("pow"),
    np.negative: lambda a: -a,
    np.absolute: _unary(np.abs, lambda x, v: np.sign(x)),
    np.tanh: _unary(np.tanh, lambda x, v: 1.0 - v * v),
    np.exp: _unary(np.exp, lambda x, v: v),
    np.log: _unary(np.log, lambda x, v: 1.0 / x),
    np.sqrt: _unary(np.sqrt, lambda x, v: 0.5 / v),
    np.sin: _unary(np.sin, lambda x, v: np.cos(x)),
    np.cos: _unary(np.cos, lambda x, v: -np.sin(x)),
    np.arctan: _unary(np.arctan, lambda x, v: 1.0 / (1.0 + x * x)),
    np.sinh: _unary(np.sinh, lambda x, v: np.cosh(x)),
    np.cosh: _unary(np.cosh, lambda x, v: np.sinh(x)),
    **{  # comparisons on the values (a NumPy scalar on the left: 0.0 < x)
        f: (lambda f: lambda a, b: f(value(a), value(b)))(f)
        for f in (np.less, np.less_equal, np.greater, np.greater_equal, np.equal, np.not_equal)
    },
    np.maximum: _maximum,
    np.minimum: _minimum,
    np.sign: _sign,
    np.matmul: _matmul,
}


def _stack(arrays: list, axis: int = 0) -> Dual:
    like = next(a for a in arrays if isinstance(a, Dual))
    ds = [_lift(a, like) for a in arrays]
    ax = axis if axis >= 0 else axis - 1  # the derivative axis stays last
    return Dual(np.stack([d.v for d in ds], axis=axis), np.stack([d.d for d in ds], axis=ax))


def _concatenate(arrays: list, axis: int = 0) -> Dual:
    like = next(a for a in arrays if isinstance(a, Dual))
    ds = [_lift(a, like) for a in arrays]
    ax = axis if axis >= 0 else axis - 1
    return Dual(np.concatenate([d.v for d in ds], axis=axis), np.concatenate([d.d for d in ds], axis=ax))


def _where(cond: Any, a: Any, b: Any) -> Dual:
    like = a if isinstance(a, Dual) else b
    a, b = _lift(a, like), _lift(b, like)
    cond = np.asarray(cond)
    return Dual(np.where(cond, a.v, b.v), np.where(_e(cond), a.d, b.d))


def _clip(a: Any, lo: Any, hi: Any) -> Dual:
    out = a if lo is None else _maximum(a, lo)
    return out if hi is None else _minimum(out, hi)


_FUNCTIONS = {np.stack: _stack, np.concatenate: _concatenate, np.where: _where, np.clip: _clip}


def supported() -> list[str]:
    """The NumPy operations a force term may use to get exact sensitivities (the refinement, the
    Cramer-Rao bound): besides + - * / ** and comparisons, these ufuncs and functions."""
    return sorted(f"np.{f.__name__}" for f in [*_UFUNCS, *_FUNCTIONS])


def unsupported(name: str) -> str:
    return (
        f"{name} has no exact sensitivity in pidyn.autodiff, which the refinement runs force terms through; "
        f"write the term with {', '.join(supported())} (docs/extending.md), or add its derivative to "
        "pidyn.autodiff"
    )


def seed(values: np.ndarray, directions: np.ndarray) -> Dual:
    """A dual array with the given values and derivative directions (``v.shape + (D,)``)."""
    return Dual(np.asarray(values, dtype=float), np.asarray(directions, dtype=float))


def value(x: Any) -> np.ndarray:
    return x.v if isinstance(x, Dual) else np.asarray(x)


def deriv(x: Any, n_dir: int) -> np.ndarray:
    if isinstance(x, Dual):
        return x.d
    v = np.asarray(x)
    return np.zeros(v.shape + (n_dir,))
