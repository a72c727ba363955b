"""The data's way: the diagnosis's fitting span followed at run time, from the task down.

Runs ``diagnose.py`` on a simulated accelerometer record (the path where the span travels
furthest: the supports' start, the nominal identification and its refinement) with a profiler that
logs every call receiving the span, with the chain of pidyn functions above it. A *climb* is a
call from a lower layer into a higher one (tasks > discrepancy > runs > starts > baselines >
refine > models > data > systems). Writes ``experiments/results/span_trace.md``.

    python experiments/span_trace.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pidyn.discrepancy.case as case_module
import pidyn.discrepancy.subjects.single_dof as single_dof
from pidyn.cli import diagnose_main

ORDER = ["tasks", "discrepancy", "runs", "starts", "baselines", "refine", "models", "data", "systems"]
OUT = Path(__file__).resolve().parent / "results" / "span_trace.md"
chains: set[tuple[str, ...]] = set()
span: tuple[float, float] | None = None


def _layer(where: str) -> int | None:
    """The layer of ``where`` ("discrepancy.case.mask": the diagnosis), None outside the order."""
    top = where.split(".")[0]
    return ORDER.index(top) if top in ORDER else None


def _profile(frame, event, arg):
    if event != "call" or span is None or not frame.f_globals.get("__name__", "").startswith("pidyn"):
        return
    if not any(_is_span(v) for v in frame.f_locals.values()):
        return
    chain, f = [], frame
    while f is not None:
        module = f.f_globals.get("__name__", "")
        if module.startswith("pidyn") and not module.startswith("pidyn.cli"):
            chain.append(f"{module.removeprefix('pidyn.')}.{f.f_code.co_name}")
        f = f.f_back
    chains.add(tuple(reversed(chain)))


def _is_span(value) -> bool:
    """The span itself (a profiler that raises is switched off: no array is compared)."""
    return (
        isinstance(value, tuple)
        and len(value) == 2
        and all(isinstance(x, float) for x in value)
        and value == span
    )


def _spy(split):
    def split_spans(record, share):
        global span
        out = split(record, share)
        span = tuple(map(float, out[0]))
        return out

    return split_spans


def main() -> None:
    spy = _spy(case_module.split_spans)
    case_module.split_spans = single_dof.split_spans = spy
    with tempfile.TemporaryDirectory() as tmp:
        sys.argv = [
            "diagnose.py",
            "data=accelerometers",
            "system=linear",
            "debug=fast",
            f"hydra.run.dir={tmp}",
        ]
        sys.setprofile(_profile)
        try:
            diagnose_main(leave=False)
        except SystemExit:
            pass
        finally:
            sys.setprofile(None)
    maximal = [c for c in chains if not any(len(o) > len(c) and o[: len(c)] == c for o in chains)]
    lines = ["# The diagnosis's fitting span, followed at run time (`experiments/span_trace.py`)", ""]
    lines += ["| stays | climbs | chain |", "|---|---|---|"]
    worst = 0
    for c in sorted(maximal, key=len):
        layers = [_layer(s) for s in c]
        climbs = [
            f"{c[i]} -> {c[i + 1]}"
            for i in range(len(c) - 1)
            if layers[i] is not None and layers[i + 1] is not None and layers[i + 1] < layers[i]
        ]
        worst = max(worst, len(climbs))
        lines.append(f"| {len(c)} | {'; '.join(climbs) or '0'} | {' > '.join(c)} |")
    lines += ["", f"Most climbs on one path: {worst}.", ""]
    OUT.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
