"""What the Silverbox circuit does that the diagnosis' cubic model misses, with evidence.

    python experiments/silverbox_models.py [--run experiments/results/silverbox] [--jobs 2]

From the diagnosis' extended model (``python diagnose.py data=silverbox system=linear``):
  1. that model refined by multiple shooting over the whole estimation part (the diagnosis
     polishes on its first 10 s), with 95 % intervals;
  2. the same refinement with the input read linearly between samples, the hold every earlier
     result used: what the hold alone costs;
  3. a forward search over force terms, each candidate refined over the whole estimation part
     and scored there by its free simulation from rest. A term is kept when it removes at least
     ``--relevance`` (5 %) of the remaining mean-square simulation error and lowers the BIC; the
     best such term is added and the search repeats. The test signals play no part in it.
Every model is then simulated on the benchmark's test signals (``benchmark_test_signals``).
Writes ``<run>/models.md`` and ``models.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: candidate force terms: label -> (kind, powers); kind "effect" names a library effect
CANDIDATES: dict[str, tuple[str, tuple[int, int]]] = {
    "quadratic_stiffness": ("effect", (2, 0)),
    "quadratic_damping": ("effect", (0, 2)),
    "x x'": ("monomial", (1, 1)),
    "x'^2": ("monomial", (0, 2)),
    "x^2 x'": ("monomial", (2, 1)),
    "x x'^2": ("monomial", (1, 2)),
    "x'^3": ("monomial", (0, 3)),
    "x^4": ("monomial", (4, 0)),
    "x^5": ("monomial", (5, 0)),
}
SKIP = 50  # samples left out after a start from rest, as on the test signals


def _terms(base: dict, added: list[str], scales: dict[str, float]):
    """The SDOF system of the base model's terms and the added candidates."""
    from pidyn.systems import SDOFSystem
    from pidyn.systems.terms import (
        CubicStiffness,
        LinearStiffness,
        Monomial,
        QuadraticDamping,
        QuadraticStiffness,
        ViscousDamping,
    )

    terms = [ViscousDamping(base["c"]), LinearStiffness(base["k"]), CubicStiffness(base["k3"])]
    for name in added:
        kind, (i, j) = CANDIDATES[name]
        if name == "quadratic_stiffness":
            terms.append(QuadraticStiffness(0.0, scale=scales[name]))
        elif name == "quadratic_damping":
            terms.append(QuadraticDamping(scales[name] * 1e-3))
        else:
            terms.append(Monomial(i, j, 0.0, scale=scales[name]))
    return SDOFSystem(terms, mass=base["m"], identify_mass=True, excitation="force", name="silverbox")


def _scales(rec) -> dict[str, float]:
    """Each candidate coefficient's natural size: the force scale over x^i x'^j's."""
    x = float(np.std(rec.x[:, 0]))
    v = x * 2 * math.pi * 69.0  # the resonance
    f = float(np.std(rec.f))
    return {name: f / (x**i * v**j) for name, (_, (i, j)) in CANDIDATES.items()}


def _fit_mse(system, values: dict, rec) -> float:
    """Mean-square free-simulation error (V^2) over the fitting part, from rest."""
    from pidyn.simulate import simulate_response

    fit = rec.segment(*rec.meta.split.fit)
    err = simulate_response(system, values, fit)["x"][:, 0] - fit.x[:, 0]
    return float(np.mean(err[SKIP:] ** 2))


def refine_model(added: list[str], start: dict, hold: str = "bandlimited") -> dict:
    """One candidate structure refined over the whole estimation part (one process)."""
    from pidyn.data.measured.silverbox import load_silverbox
    from pidyn.refine.stage import RefineSettings, refine

    rec = load_silverbox()
    rec.meta.input_hold = hold
    system = _terms(start, added, _scales(rec))
    init = {s.name: s.init for s in system.param_specs()}
    init.update({k: v for k, v in start.items() if k in init})
    t0 = time.perf_counter()
    settings = RefineSettings(segment_length=1.0, states="simulated", initial_state="rest")
    lo, hi = rec.meta.split.fit
    res = refine(system, rec, {"start": init}, settings, t_start=lo, t_end=hi, prefer="start")
    return {
        "added": added,
        "hold": hold,
        "params": res.params,
        "intervals": {k: v["ci95"] for k, v in res.intervals.items()},
        "equation": system.describe(res.params),
        "fit_mse": _fit_mse(system, res.params, rec),
        "n_fit": int(len(rec.segment(*rec.meta.split.fit).t) - SKIP),
        "converged": bool(res.converged),
        "seconds": time.perf_counter() - t0,
    }


def test_errors(model: dict) -> dict:
    from benchmark_test_signals import silverbox_errors

    from pidyn.data.measured.silverbox import load_silverbox

    system = _terms(model["params"], model["added"], _scales(load_silverbox()))
    return silverbox_errors(system, model["params"], hold=model["hold"])


def _bic(m: dict) -> float:
    k = 4 + len(m["added"])
    return m["n_fit"] * math.log(m["fit_mse"]) + k * math.log(m["n_fit"])


def search(start: dict, jobs: int, relevance: float, max_terms: int, log) -> list[dict]:
    """Forward selection over ``CANDIDATES``; the accepted models, the refined cubic first."""
    from joblib import Parallel, delayed

    chain = [refine_model([], start)]
    log(f"cubic, refined: fit RMS {1e3 * math.sqrt(chain[0]['fit_mse']):.4f} mV")
    while len(chain[-1]["added"]) < max_terms:
        cur = chain[-1]
        left = [c for c in CANDIDATES if c not in cur["added"]]
        tried = Parallel(n_jobs=jobs)(delayed(refine_model)(cur["added"] + [c], cur["params"]) for c in left)
        for m in tried:
            m["removed"] = 1 - m["fit_mse"] / cur["fit_mse"]
            m["delta_bic"] = _bic(m) - _bic(cur)
            log(f"  + {m['added'][-1]}: removes {100 * m['removed']:.1f} %, dBIC {m['delta_bic']:.0f}")
        cur["tried"] = [{k: m[k] for k in ("added", "removed", "delta_bic", "equation")} for m in tried]
        ok = [m for m in tried if m["removed"] >= relevance and m["delta_bic"] < 0]
        if not ok:
            break
        chain.append(max(ok, key=lambda m: m["removed"]))
        log(f"kept {chain[-1]['added'][-1]}: {chain[-1]['equation']}")
    return chain


def _table(chain: list[dict], linear: dict, errors: list[dict], published: list[dict]) -> list[str]:
    from benchmark_test_signals import SILVERBOX_SIGNALS

    sig = list(SILVERBOX_SIGNALS)
    rows = [
        "| model | hold | fit RMS (mV) | " + " | ".join(f"{s} (mV)" for s in sig) + " | equation |",
        "|---|---|---|" + "---|" * len(sig) + "---|",
    ]
    for m, e in zip([linear, *chain], errors):
        name = "cubic (the diagnosis' model)" + "".join(f" + {a}" for a in m["added"])
        vals = " | ".join(f"{e[s]['rms_error']:.4f}" for s in sig)
        rows.append(
            f"| {name} | {m['hold']} | {1e3 * math.sqrt(m['fit_mse']):.4f} | {vals} | `{m['equation']}` |"
        )
    for p in published:
        vals = " | ".join(f"{p.get(s, '-')}" for s in sig)
        rows.append(f"| {p['method']} (published) | - | - | {vals} | {p['source']} |")
    return rows


def _search_lines(chain: list[dict]) -> list[str]:
    out = ["| step | candidate | removes of the fit MSE | dBIC | kept |", "|---|---|---|---|---|"]
    for step, m in enumerate(chain):
        kept = chain[step + 1]["added"][-1] if step + 1 < len(chain) else None
        for t in sorted(m.get("tried", []), key=lambda r: -r["removed"]):
            name = t["added"][-1]
            out.append(
                f"| {step + 1} | {name} | {100 * t['removed']:.1f} % | {t['delta_bic']:.0f} | "
                f"{'**yes**' if name == kept else ''} |"
            )
    return out


def _intervals(m: dict) -> list[str]:
    out = ["| parameter | value | 95 % interval |", "|---|---|---|"]
    for k, v in m["params"].items():
        lo, hi = m["intervals"].get(k, [float("nan")] * 2)
        out.append(f"| {k} | {v:.6g} | [{lo:.6g}, {hi:.6g}] |")
    return out


def arrow_lines(model: dict) -> list[str]:
    """Where on the arrow-head record the final model's error lies: per eighth of it, the RMS and
    mean error and the signal's spread, against the largest output of the estimation part."""
    from benchmark_test_signals import SILVERBOX_SIGNALS, silverbox_arrays, simulate

    from pidyn.data.measured.silverbox import FS, load_silverbox

    rec = load_silverbox()
    fit_peak = float(np.max(np.abs(rec.segment(*rec.meta.split.fit).x[:, 0])))
    u, y = silverbox_arrays()
    lo, hi = SILVERBOX_SIGNALS["arrow (full)"]
    system = _terms(model["params"], model["added"], _scales(rec))
    err = (simulate(system, model["params"], u[lo:hi], FS, hold="bandlimited") - y[lo:hi])[SKIP:]
    yy = y[lo:hi][SKIP:]
    out = [
        f"The arrow-head record, simulated by the final model (mean error {1e3 * err.mean():.3f} mV over "
        f"the whole record; the largest output of the estimation part is {1e3 * fit_peak:.0f} mV):",
        "",
        "| eighth | RMS error (mV) | mean error (mV) | output std (mV) | output peak (mV) |",
        "|---|---|---|---|---|",
    ]
    n = len(err)
    for q in range(8):
        sl = slice(q * n // 8, (q + 1) * n // 8)
        out.append(
            f"| {q + 1} | {1e3 * np.sqrt(np.mean(err[sl] ** 2)):.3f} | {1e3 * err[sl].mean():.3f} | "
            f"{1e3 * yy[sl].std():.1f} | {1e3 * np.max(np.abs(yy[sl])):.0f} |"
        )
    return out


def _published() -> list[dict]:
    from benchmark_test_signals import PUBLISHED

    pub: dict[str, dict] = {}
    for p in PUBLISHED["silverbox"]:
        pub.setdefault(p["method"], {"method": p["method"], "source": p["source"]})[p["signal"]] = p[
            "rms_error"
        ]
    return list(pub.values())


def _compare_lines(final_errors: dict, published: list[dict]) -> list[str]:
    best = published[0]
    out = []
    for sig, e in final_errors.items():
        ratio = e["rms_error"] / best[sig]
        verdict = "at or below" if ratio <= 1 else "above"
        out.append(
            f"- {sig}: {e['rms_error']:.3f} mV, {ratio:.2f} times the best published {best[sig]} mV ({verdict})"
        )
    return out


def write_report(run: Path, out: dict, header: str) -> None:
    chain, linear, errors = out["chain"], out["linear_hold"], out["test_errors"]
    final, pub = chain[-1], _published()
    lines = [
        "# Silverbox: what the cubic model misses",
        "",
        header,
        "",
        "## Test signals",
        "",
        *_table(chain, linear, errors, pub),
        "",
        "The final model against the best published figure:",
        "",
        *_compare_lines(errors[-1], pub),
        "",
        *arrow_lines(final),
        "",
        "## The search (fitting part only)",
        "",
        *_search_lines(chain),
        "",
        f"## The final model, with 95 % intervals\n\n`{final['equation']}`",
        "",
        *_intervals(final),
    ]
    (run / "models.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=ROOT / "experiments" / "results" / "silverbox")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--relevance", type=float, default=0.05)
    ap.add_argument("--max-terms", type=int, default=3)
    ap.add_argument("--report-only", action="store_true", help="models.md again from models.json")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from joblib import Parallel, delayed

    if args.report_only:
        out = json.loads((args.run / "models.json").read_text())
        write_report(args.run, out, out["header"])
        return
    d = json.loads((args.run / "diagnosis.json").read_text())
    if d.get("causes") != ["cubic_stiffness"]:
        raise SystemExit(
            f"{args.run}: the diagnosis named {d.get('causes')}; this study starts from the cubic spring"
        )
    t0 = time.perf_counter()
    log = lambda s: print(f"[{time.perf_counter() - t0:6.0f} s] {s}", flush=True)  # noqa: E731
    start = {k: d["extended_parameters"][k] for k in ("m", "c", "k", "k3")}
    chain = search(start, args.jobs, args.relevance, args.max_terms, log)
    linear = refine_model([], start, hold="linear")
    errors = Parallel(n_jobs=args.jobs)(delayed(test_errors)(m) for m in [linear, *chain])
    shown = args.run.relative_to(ROOT) if args.run.is_relative_to(ROOT) else args.run
    header = (
        f"Command: `python experiments/silverbox_models.py --run {shown}` ({time.perf_counter() - t0:.0f} s, "
        f"{args.jobs} jobs). Every model refined by multiple shooting (1 s segments, from rest) over the whole "
        "estimation part and simulated from rest on the test signals, which play no part in the search. A term "
        f"is kept when it removes at least {100 * args.relevance:.0f} % of the fitting part's mean-square "
        "simulation error and lowers the BIC."
    )
    out = {"header": header, "chain": chain, "linear_hold": linear, "test_errors": errors}
    (args.run / "models.json").write_text(json.dumps(out, indent=1, default=float))
    write_report(args.run, out, header)
    log(f"wrote {args.run / 'models.md'}")


if __name__ == "__main__":
    main()
