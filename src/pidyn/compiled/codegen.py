"""C source of a compiled RK4 loop from a tape (``pidyn.compiled.tape``).

The loop is ``pidyn.integrate._steps`` written out in C, operation for operation in the same
order, so that plain and dual results agree with it to round-off. Nodes that depend on the
parameters and constants alone (a deck's influence coefficients, 1/m) are computed once per
trajectory. The dual variant carries ``D`` derivative directions with the same rules as
``pidyn.autodiff.Dual``. Constants are read from an array passed at run time, so that models
that differ only in their constants (a friction's smoothing width, a record's amplitude
scale) share one compiled library.
"""

from __future__ import annotations

from dataclasses import dataclass

from pidyn.compiled.dopri_template import SOURCE as TRUTH
from pidyn.compiled.heun_template import SOURCE as HEUN
from pidyn.compiled.rk4_template import TEMPLATE
from pidyn.compiled.tape import Tape

#: a node's value from its operands' values
_VALUE = {
    "add": "{0} + {1}",
    "sub": "{0} - {1}",
    "mul": "{0} * {1}",
    "div": "{0} / {1}",
    "neg": "-{0}",
    "pow": "pow({0}, {1})",
    "sqrtpow": "sqrt({0})",
    "abs": "fabs({0})",
    "tanh": "tanh({0})",
    "exp": "exp({0})",
    "log": "log({0})",
    "sqrt": "sqrt({0})",
    "sin": "sin({0})",
    "cos": "cos({0})",
    "arctan": "atan({0})",
    "sinh": "sinh({0})",
    "cosh": "cosh({0})",
    "max": "({0} >= {1} ? {0} : {1})",
    "min": "({0} <= {1} ? {0} : {1})",
    "sign": "(double)(({0} > 0) - ({0} < 0))",
    "lt": "(double)({0} < {1})",
    "le": "(double)({0} <= {1})",
    "gt": "(double)({0} > {1})",
    "ge": "(double)({0} >= {1})",
    "eq": "(double)({0} == {1})",
    "ne": "(double)({0} != {1})",
    "select": "({0} != 0.0 ? {1} : {2})",
}
#: d(node) from d(operand): the factor each operand's derivative is multiplied by ({v}: the node)
_CHAIN = {
    "abs": "(double)(({0} > 0) - ({0} < 0))",
    "tanh": "(1.0 - {v} * {v})",
    "exp": "{v}",
    "log": "(1.0 / {0})",
    "sqrt": "(0.5 / {v})",
    "sqrtpow": "(0.5 / {v})",
    "sin": "cos({0})",
    "cos": "(-sin({0}))",
    "arctan": "(1.0 / (1.0 + {0} * {0}))",
    "sinh": "cosh({0})",
    "cosh": "sinh({0})",
}
_NO_DERIVATIVE = {"sign", "lt", "le", "gt", "ge", "eq", "ne"}
LEAVES = ("time", "state", "input", "param", "const")


@dataclass
class Plan:
    """What the code needs to know of the tape: the constants' values, which nodes are computed
    once per trajectory, and which carry derivatives."""

    constants: list[float]
    invariant: list[bool]
    carries: list[bool]


def plan(tape: Tape) -> Plan:
    constants: list[float] = []
    invariant, carries = [], []
    for op, *args in tape.nodes:
        if op == "const":
            constants.append(float.fromhex(args[0]))
            invariant.append(True)
            carries.append(False)
        elif op in LEAVES:
            invariant.append(op == "param")
            carries.append(op in ("param", "state"))
        else:
            invariant.append(all(invariant[a] for a in args))
            operands = args[1:] if op == "select" else args
            carries.append(op not in _NO_DERIVATIVE and any(carries[a] for a in operands))
    return Plan(constants, invariant, carries)


class _Names:
    """How the code names each node's value, and its derivative along direction k."""

    def __init__(self, tape: Tape, pl: Plan) -> None:
        self.tape, self.pl = tape, pl
        self.const: dict[int, int] = {}
        self.inv: dict[int, int] = {}
        for i, (op, *_) in enumerate(tape.nodes):
            if op == "const":
                self.const[i] = len(self.const)
            elif pl.invariant[i] and op != "param":
                self.inv[i] = len(self.inv)

    def value(self, i: int) -> str:
        op, *args = self.tape.nodes[i]
        if op == "const":
            return f"K[{self.const[i]}]"
        if op == "param":
            return f"P[{args[0]}]"
        if op == "time":
            return "t"
        if op == "state":
            return f"y[{args[0]}]"
        if op == "input":
            return f"f[{args[0]}]"
        return f"I[{self.inv[i]}]" if self.pl.invariant[i] else f"v{i}"

    def deriv(self, i: int) -> str | None:
        """Node i's derivative along direction ``k``, None where it has none."""
        if not self.pl.carries[i]:
            return None
        op, *args = self.tape.nodes[i]
        if op == "param":
            return f"dP[{args[0]} * D + k]"
        if op == "state":
            return f"yd[{args[0]} * D + k]"
        return f"Id[{self.inv[i]} * D + k]" if self.pl.invariant[i] else f"d{i}"


def _op_of(tape: Tape, i: int) -> str:
    op, *args = tape.nodes[i]
    if op == "pow" and tape.nodes[args[1]] == ("const", (0.5).hex()):
        return "sqrtpow"  # NumPy takes x ** 0.5 by a square root
    return op


def _value_line(tape: Tape, names: _Names, i: int) -> str:
    a = [names.value(j) for j in tape.nodes[i][1:]]
    decl = "" if names.pl.invariant[i] else "const double "
    return f"{decl}{names.value(i)} = {_VALUE[_op_of(tape, i)].format(*a)};"


def _factor_line(tape: Tape, names: _Names, i: int) -> str | None:
    """A unary operation's chain factor (or a power's two), computed once, before the directions."""
    op, *args = _op_of(tape, i), *tape.nodes[i][1:]
    a, v = [names.value(j) for j in args], names.value(i)
    if op in _CHAIN and names.pl.carries[i]:
        return f"const double c{i} = {_CHAIN[op].format(*a, v=v)};"
    if op == "pow" and names.pl.carries[i]:
        base = f"fmax({a[0]}, 1e-300)" if names.pl.carries[args[0]] else a[0]
        return f"const double c{i} = {a[1]} * pow({a[0]}, {a[1]} - 1), e{i} = {v} * log({base});"
    return None


def _deriv_line(tape: Tape, names: _Names, i: int) -> str | None:
    if not names.pl.carries[i]:
        return None
    op, *args = _op_of(tape, i), *tape.nodes[i][1:]
    chain = _chain(op, i, [names.value(j) for j in args], [names.deriv(j) for j in args], names.value(i))
    target = names.deriv(i)
    return f"{target} = {chain};" if names.pl.invariant[i] else f"const double {target} = {chain};"


def _chain(op: str, i: int, a: list[str], da: list[str | None], v: str) -> str:
    """The derivative along one direction, in the order ``pidyn.autodiff.Dual`` computes it."""
    if op == "add":
        return f"{da[0]} + {da[1]}" if all(da) else str(da[0] or da[1])
    if op == "sub":
        return f"{da[0]} - {da[1]}" if all(da) else (da[0] or f"-{da[1]}")
    if op == "neg":
        return f"-{da[0]}"
    if op == "mul":
        parts = [f"{da[0]} * {a[1]}" if da[0] else None, f"{da[1]} * {a[0]}" if da[1] else None]
        return " + ".join(x for x in parts if x)
    if op == "div":
        if da[1] is None:
            return f"{da[0]} / {a[1]}"
        if da[0] is None:
            return f"-{da[1]} * ({v} / {a[1]})"
        return f"({da[0]} - {da[1]} * {v}) / {a[1]}"
    if op == "pow":
        parts = [f"{da[0]} * c{i}" if da[0] else None, f"{da[1]} * e{i}" if da[1] else None]
        return " + ".join(x for x in parts if x)
    if op in ("max", "min"):
        cmp = ">=" if op == "max" else "<="
        return f"({a[0]} {cmp} {a[1]} ? {da[0] or '0.0'} : {da[1] or '0.0'})"
    if op == "select":
        return f"({a[0]} != 0.0 ? {da[1] or '0.0'} : {da[2] or '0.0'})"
    return f"{da[0]} * c{i}"


def _block(tape: Tape, names: _Names, nodes: list[int], dual: bool, tail: list[str]) -> str:
    """Values first; with derivatives, the chain factors and then one loop over the directions
    (scalar locals, one direction at a time: short code that compiles quickly)."""
    lines = [_value_line(tape, names, i) for i in nodes]
    if dual:
        lines += [x for i in nodes if (x := _factor_line(tape, names, i))]
        inner = [x for i in nodes if (x := _deriv_line(tape, names, i))]
        lines += ["for (int k = 0; k < D; k++) {", *["    " + x for x in inner + tail], "}"]
    return "\n    ".join(lines)


def source(tape: Tape, n_param: int, n_state: int, n_input: int, along: bool = False) -> str:
    """The C source of ``run`` (see ``pidyn.compiled.kernel``) for this tape, and of ``truth``
    (``pidyn.compiled.dopri_template``) for a state rate or, with ``along`` (a latent rate along a
    given motion, ``tape.record_latent``), of ``heun`` (``pidyn.compiled.heun_template``)."""
    pl = plan(tape)
    names = _Names(tape, pl)
    body = [i for i, (op, *_) in enumerate(tape.nodes) if op not in LEAVES]
    inv = [i for i in body if pl.invariant[i]]
    var = [i for i in body if not pl.invariant[i]]
    out = [f"out[{j}] = {names.value(i)};" for j, i in enumerate(tape.outputs)]
    outd = [f"outd[{j} * D + k] = {names.deriv(i) or '0.0'};" for j, i in enumerate(tape.outputs)]
    return TEMPLATE.format(
        NP=n_param,
        NS=n_state,
        NW=n_input,
        NI=max(len(names.inv), 1),
        prologue=_block(tape, names, inv, False, []),
        prologue_d=_block(tape, names, inv, True, []),
        rate=_block(tape, names, var, False, []) + "\n    " + "\n    ".join(out),
        rate_d="\n    ".join([_block(tape, names, var, True, outd), *out]),
    ) + (HEUN if along else TRUTH)
