"""Record a system's state rate as a flat list of scalar operations (a tape).

The force terms are written once on array operations (``pidyn.systems.terms``); NumPy arrays,
dual numbers and torch tensors go through the same code. A ``Traced`` array goes through it
too and records what it does: every scalar result is a node of the tape, built once for
equal operations on equal inputs. The tape is what ``pidyn.compiled.codegen`` turns into a
compiled RK4 loop. Code the tape cannot follow (a branch on a value, a conversion to float,
an operation it does not know) raises ``NotTraceable``, and the caller integrates in Python.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pidyn.autodiff import Dual


class NotTraceable(TypeError):
    """The state rate does something a tape cannot record."""


@dataclass
class Tape:
    """Nodes in the order they were made: ``(op, *args)`` with args the operands' node indices.

    Leaves are ``("param", j)``, ``("state", j)``, ``("input", w)`` (the excitation's column
    w), ``("time",)`` and ``("const", hex)`` (a float by ``float.hex``, so that -0.0 and NaN
    keep their own nodes); ``outputs`` are the state rate's entries as node indices."""

    nodes: list[tuple] = field(default_factory=list)
    index: dict[tuple, int] = field(default_factory=dict)
    outputs: list[int] = field(default_factory=list)

    def node(self, op: str, *args: Any) -> int:
        key = (op, *args)
        found = self.index.get(key)
        if found is None:
            found = self.index[key] = len(self.nodes)
            self.nodes.append(key)
        return found


class Node:
    """One scalar of a traced computation: its index in the tape."""

    __slots__ = ("i",)

    def __init__(self, i: int) -> None:
        self.i = i

    def __bool__(self) -> bool:
        raise NotTraceable("a branch on a traced value")

    def __float__(self) -> float:
        raise NotTraceable("a traced value converted to float")

    # arithmetic on the scalars of an object array (``np.asarray`` of a traced array)
    __neg__ = lambda self: _op("neg", self)  # noqa: E731
    __add__ = lambda self, o: _op("add", self, o)  # noqa: E731
    __radd__ = lambda self, o: _op("add", o, self)  # noqa: E731
    __sub__ = lambda self, o: _op("sub", self, o)  # noqa: E731
    __rsub__ = lambda self, o: _op("sub", o, self)  # noqa: E731
    __mul__ = lambda self, o: _op("mul", self, o)  # noqa: E731
    __rmul__ = lambda self, o: _op("mul", o, self)  # noqa: E731
    __truediv__ = lambda self, o: _op("div", self, o)  # noqa: E731
    __rtruediv__ = lambda self, o: _op("div", o, self)  # noqa: E731
    __pow__ = lambda self, o: _pow(self, o)  # noqa: E731


class _Recording(threading.local):
    """The tapes being recorded, innermost last: one stack per thread, so threads trace apart."""

    def __init__(self) -> None:
        self.tapes: list[Tape] = []


_RECORDING = _Recording()


def _number(x: Any) -> float:
    if isinstance(x, (bool, np.bool_, int, float, np.integer, np.floating)):
        return float(x)
    raise NotTraceable(f"a {type(x).__name__} inside a traced operation")


def _arg(x: Any) -> int:
    """An operand's node index (a float becomes a constant node)."""
    if isinstance(x, Node):
        return x.i
    return _RECORDING.tapes[-1].node("const", _number(x).hex())


def _op(name: str, *xs: Any) -> Any:
    """A scalar operation: folded to a float when every operand is one (as NumPy computes it on
    float64), else a node."""
    if not any(isinstance(x, Node) for x in xs):
        with np.errstate(all="ignore"):
            return float(_NUMPY[name](*[np.float64(_number(x)) for x in xs]))
    return Node(_RECORDING.tapes[-1].node(name, *[_arg(x) for x in xs]))


def _pow(a: Any, b: Any) -> Any:
    if not isinstance(b, Node) and float(b) == 2.0:  # NumPy squares by a product
        return _op("mul", a, a)
    return _op("pow", a, b)


#: what each operation computes, for folding constants (the C of each: ``pidyn.compiled.codegen``)
_NUMPY = {
    "add": np.add,
    "sub": np.subtract,
    "mul": np.multiply,
    "div": np.true_divide,
    "neg": np.negative,
    "pow": np.power,
    "abs": np.absolute,
    "tanh": np.tanh,
    "exp": np.exp,
    "log": np.log,
    "sqrt": np.sqrt,
    "sin": np.sin,
    "cos": np.cos,
    "arctan": np.arctan,
    "sinh": np.sinh,
    "cosh": np.cosh,
    "max": lambda a, b: a if a >= b else b,
    "min": lambda a, b: a if a <= b else b,
    "sign": np.sign,
    "lt": np.less,
    "le": np.less_equal,
    "gt": np.greater,
    "ge": np.greater_equal,
    "eq": np.equal,
    "ne": np.not_equal,
    "select": lambda c, a, b: a if c else b,
}
#: the ufuncs a traced array records, by the operation's name (max, min and select aside)
_RECORDED = {u: name for name, u in _NUMPY.items() if isinstance(u, np.ufunc)}

_UFUNCS: dict[Any, Any] = {
    **{u: (lambda n: lambda *xs: _op(n, *xs))(n) for u, n in _RECORDED.items()},
    np.power: _pow,
    np.positive: lambda a: a,
    np.maximum: lambda a, b: _op("max", a, b),
    np.minimum: lambda a, b: _op("min", a, b),
}
_VECTORISED = {u: np.frompyfunc(fn, u.nin, 1) for u, fn in _UFUNCS.items()}
_SELECT = np.frompyfunc(lambda c, a, b: _op("select", c, a, b), 3, 1)


def _objects(x: Any) -> np.ndarray:
    """An operand as an object array of nodes and floats."""
    if isinstance(x, Traced):
        return x.a
    if isinstance(x, (Dual, Node)) or hasattr(x, "detach"):
        raise NotTraceable(f"a {type(x).__name__} beside a traced value")
    arr = np.asarray(x)
    if arr.dtype == object:
        return arr
    return arr.astype(float).astype(object)


class Traced(np.lib.mixins.NDArrayOperatorsMixin):
    """An array of traced scalars: NumPy's operators, ufuncs and the array functions the systems
    use record themselves on the tape."""

    __array_priority__ = 2000

    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    shape = property(lambda self: self.a.shape)
    ndim = property(lambda self: self.a.ndim)

    def __len__(self) -> int:
        return len(self.a)

    def __getitem__(self, idx: Any) -> Traced:
        return Traced(np.asarray(self.a[idx], dtype=object))

    def __bool__(self) -> bool:
        raise NotTraceable("a branch on a traced value")

    def __float__(self) -> float:
        raise NotTraceable("a traced value converted to float")

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        if dtype is not None and np.dtype(dtype) != object:
            raise NotTraceable("a traced value converted to a numeric array")
        return self.a

    def __array_ufunc__(self, ufunc: np.ufunc, method: str, *inputs: Any, **kw: Any) -> Any:
        if ufunc is np.matmul and method == "__call__" and not kw:  # a network's layer: sums of products
            return _wrap(np.matmul(*[_objects(x) for x in inputs]))
        fn = _VECTORISED.get(ufunc)
        if method != "__call__" or kw or fn is None:
            raise NotTraceable(f"np.{ufunc.__name__}" + ("" if method == "__call__" else f".{method}"))
        return _wrap(fn(*[_objects(x) for x in inputs]))

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        fn = _FUNCTIONS.get(func)
        if fn is None:
            raise NotTraceable(f"np.{getattr(func, '__name__', func)}")
        return fn(*args, **kwargs)

    def clip(self, lo: Any = None, hi: Any = None) -> Traced:
        return _clip(self, lo, hi)


def _wrap(out: Any) -> Traced:
    return Traced(np.asarray(out, dtype=object))


def _clip(a: Any, lo: Any = None, hi: Any = None) -> Traced:
    out = a if lo is None else np.maximum(a, lo)
    return out if hi is None else np.minimum(out, hi)


_FUNCTIONS: dict[Any, Any] = {
    np.stack: lambda arrays, axis=0: _wrap(np.stack([_objects(a) for a in arrays], axis=axis)),
    np.concatenate: lambda arrays, axis=0: _wrap(np.concatenate([_objects(a) for a in arrays], axis=axis)),
    np.where: lambda c, a, b: _wrap(_SELECT(_objects(c), _objects(a), _objects(b))),
    np.clip: _clip,
    np.broadcast_to: lambda a, shape: _wrap(np.broadcast_to(_objects(a), shape)),
    np.expand_dims: lambda a, axis: _wrap(np.expand_dims(_objects(a), axis)),
    np.shape: lambda a: a.shape,
    np.ndim: lambda a: a.ndim,
}


def leaf(kind: str, j: int | None = None) -> Node:
    tape = _RECORDING.tapes[-1]
    return Node(tape.node(kind) if j is None else tape.node(kind, j))


def _record(rate: Any, param_names: list[str], n_out: int, what: str) -> Tape:
    """The tape of ``rate(t, p)`` (its other leaves made by the caller's closure): parameters
    ``param_names`` in that order and the time as leaves, ``n_out`` outputs of shape (1, n_out)."""
    tape = Tape()
    _RECORDING.tapes.append(tape)
    try:
        t = Traced(np.array([leaf("time")], dtype=object))
        p = {name: Traced(np.array(leaf("param", j), dtype=object)) for j, name in enumerate(param_names)}
        with np.errstate(all="ignore"):
            out = rate(t, p)
        if not isinstance(out, Traced) or out.shape != (1, n_out):
            raise NotTraceable(f"the {what} came back as {type(out).__name__} {getattr(out, 'shape', '')}")
        tape.outputs = [_arg(x) for x in out.a[0]]
    finally:
        _RECORDING.tapes.pop()
    return tape


def _row(kind: str, n: int) -> Traced:
    """One row of ``n`` leaves of a kind (the state: ``("state", j)``)."""
    return Traced(np.array([[leaf(kind, j) for j in range(n)]], dtype=object))


def record(system: Any, param_names: list[str], n_inputs: int) -> Tape:
    """The tape of ``system.state_rate`` for one trajectory: parameters ``param_names`` (in that
    order), the state, the excitation's ``n_inputs`` columns and the time as leaves."""

    def rate(t: Traced, p: dict) -> Any:
        cols = [leaf("input", w) for w in range(n_inputs)]
        f = Traced(np.array([cols] if system.n_inputs > 1 else cols, dtype=object))
        return system.state_rate(t, _row("state", system.n_state), p, f)

    return _record(rate, param_names, system.n_state, "state rate")


def record_latent(term: Any, param_names: list[str]) -> Tape:
    """The tape of ``term.latent_rate`` for one parameter set: parameters ``param_names`` (in that
    order), the latent state as the state, the motion's x and x' as inputs 0 and 1, the time."""

    def rate(t: Traced, p: dict) -> Any:
        x, v = (Traced(np.array([leaf("input", j)], dtype=object)) for j in (0, 1))
        return term.latent_rate(t, x, v, _row("state", term.n_latent), p)

    return _record(rate, param_names, term.n_latent, "latent rate")
