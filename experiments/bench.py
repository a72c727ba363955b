"""Speed and accuracy benchmark; writes experiments/results/bench.{md,json}.

    python experiments/bench.py            # per-iteration cost, Lightning overhead, end-to-end runs
    python experiments/bench.py --quick    # skip the end-to-end runs
    python experiments/bench.py --simulation  # only the simulation section, into the last results

Measures (one thread, CPU):
  * ms per training iteration (500 collocation points, x, x', x'') for the Taylor-mode
    network against nested autograd, in float32 and float64;
  * Lightning's overhead against a plain PyTorch loop driving the same module;
  * end-to-end wall time and parameter errors of `python train.py` (Duffing) and
    `python train.py system=bouc_wen`;
  * the cost against the number of storeys of a shear building measured by accelerometers on
    every floor (3, 5, 10): ms per PIDynNet iteration, ms per refinement linearisation
    (residuals and exact Jacobian over 20 s of El Centro), and the peak memory of a process
    doing both (each size in its own process, so the peaks do not mix);
  * simulation: ground truth (LSODA) of 25 s, one output-error step and one refinement
    linearisation, for a Duffing oscillator, Bouc-Wen and a 3-storey building; a linear
    model's exact sensitivities by its RK4 scheme's one-sample map against the general loop;
  * where a GPU is present, the same training steps on it (module and window moved as
    ``trainer=gpu`` moves them), beside the CPU's.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results"


def _setup(dtype):
    from pidyn.data.sources import synthetic
    from pidyn.data.windows import make_windows
    from pidyn.models.pidynnet import PIDynNet
    from pidyn.nets import TaylorMLP
    from pidyn.systems import Duffing

    torch.set_default_dtype(dtype)
    torch.manual_seed(0)
    s = Duffing()
    rec = synthetic(s, "kobe", duration=12.0, dt=0.01)
    w = make_windows(rec.t, rec.f, rec.x, rec.v, None, 3.0, 1000)[3]  # no transform: both modes fit x itself
    net = PIDynNet(s, TaylorMLP())
    net.enter_window(w)
    return net, w


def per_iteration_ms(dtype, mode: str, n: int = 200) -> float:
    net, w = _setup(dtype)

    def autograd_physics(t, f):
        t = t.clone().requires_grad_(True)
        x = net.rpn(t)
        v = torch.autograd.grad(x.sum(), t, create_graph=True)[0][:, None]
        a = torch.autograd.grad(v.sum(), t, create_graph=True)[0][:, None]
        from pidyn.systems.base import Kinematics

        r = net.system.residual(Kinematics(t, x, v, a), f, net.params.values())["motion"]
        return {"physics/motion": ((r / net.scale_f) ** 2).mean()}

    return _ms_per_step(net, w, net.physics_losses if mode == "taylor" else autograd_physics, warmup=20, n=n)


def _ms_per_step(net, w, physics, warmup: int, n: int, device: str = "cpu") -> float:
    """ms per Adam step on 500 of the window's 1000 collocation points plus the data loss,
    on ``device`` (the module and the window moved there, as ``trainer=gpu`` does)."""
    net.to(device)
    w = w.to(device)
    opt = torch.optim.Adam(list(net.parameters()), lr=1e-3)
    g = torch.Generator().manual_seed(0)
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)

    def step():
        idx = torch.randperm(1000, generator=g)[:500].to(device)
        L = physics(w.t_pool[idx], w.f_pool[idx])
        L.update(net.data_losses(w))
        opt.zero_grad()
        sum(L.values()).backward()
        opt.step()

    for _ in range(warmup):
        step()
    sync()
    t0 = time.perf_counter()
    for _ in range(n):
        step()
    sync()
    return 1e3 * (time.perf_counter() - t0) / n


def gpu_ms(n: int = 200) -> dict:
    """The same steps on the GPU, when there is one: the Duffing step in float32 / float64 and
    the shear buildings' step (Taylor-mode derivatives)."""
    if not torch.cuda.is_available():
        return {"device": None}
    out: dict = {"device": torch.cuda.get_device_name(0)}
    for name, dt in (("float32", torch.float32), ("float64", torch.float64)):
        net, w = _setup(dt)
        out[f"taylor/{name}"] = _ms_per_step(net, w, net.physics_losses, warmup=20, n=n, device="cuda")
    torch.set_default_dtype(torch.float32)
    for storeys in STOREYS:
        net, w = _building_window(storeys)
        out[f"storeys/{storeys}"] = _ms_per_step(
            net, w, net.physics_losses, warmup=10, n=n // 2, device="cuda"
        )
    return out


STOREYS = (3, 5, 10)


def _building_window(n: int, with_record: bool = False):
    """An n-storey building's PIDynNet on its third 3 s window of El Centro (accelerometers)."""
    from pidyn.data.sources import synthetic
    from pidyn.data.windows import make_windows
    from pidyn.models.pidynnet import PIDynNet
    from pidyn.nets import TaylorMLP
    from pidyn.systems import ShearBuilding

    torch.manual_seed(0)
    sb = ShearBuilding(n_storeys=n)
    rec = synthetic(sb, "el_centro", duration=20.0, channels=("a",))
    w = make_windows(rec.t, rec.f, None, None, rec.a, 3.0, 1000, accel_signal=rec.f)[2]
    net = PIDynNet(sb, TaylorMLP(out_features=n))
    net.enter_window(w)
    return (net, w, sb, rec) if with_record else (net, w)


def storey_cost(n: int, iters: int = 100) -> dict:
    """One building size: PIDynNet ms / iteration, refinement ms / linearisation, peak RSS."""
    import resource

    import numpy as np

    from pidyn.refine import RefineSettings
    from pidyn.refine.setup import build_problem

    torch.set_default_dtype(torch.float32)
    net, w, sb, rec = _building_window(n, with_record=True)
    ms_iter = _ms_per_step(net, w, net.physics_losses, warmup=10, n=iters)
    problem = build_problem(sb, rec, RefineSettings(initial_state="free"))
    b = problem.bounds[:-1]
    states = np.hstack([rec.clean.x[b], rec.clean.v[b]])  # the true segment starts (linear: no latent z)
    u = problem.pack(sb.true_values(), states)
    problem.linearize(u)
    t0 = time.perf_counter()
    reps = 3
    for _ in range(reps):
        problem.linearize(u)
    ms_lin = 1e3 * (time.perf_counter() - t0) / reps
    return {
        "storeys": n,
        "unknowns": int(problem.n_unknowns),
        "ms_per_iteration": ms_iter,
        "ms_per_linearisation": ms_lin,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def storey_scaling() -> list[dict]:
    out = []
    for n in STOREYS:  # each in a process of its own: the peak memory is that size's
        res = subprocess.run(
            [sys.executable, __file__, "--storey-cost", str(n)],
            check=True,
            capture_output=True,
            text=True,
            cwd=ROOT,
        )
        out.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print(out[-1], flush=True)
    return out


def simulation_ms(reps: int = 3) -> list[dict]:
    """What simulation costs, the work behind data, refinement, output error and diagnosis:
    ground truth (rtol 1e-10: Dormand-Prince in C, the default, and LSODA calling back into Python)
    of 25 s at dt 0.01 s, and over the same record one free run,
    one output-error step (residuals and finite-difference Jacobian, one RK4 batch) and one
    refinement linearisation (residuals and exact Jacobian by dual numbers, 1 s segments), each
    by the compiled loop (``pidyn.compiled``) and by the loop in Python (``PIDYN_COMPILED=0``)."""
    import os

    import numpy as np

    from pidyn.data.sources import synthetic_from_motion
    from pidyn.excitation import prepare
    from pidyn.integrate import rk4
    from pidyn.refine import RefineSettings, ShootingProblem
    from pidyn.refine.setup import build_problem
    from pidyn.simulate import simulate
    from pidyn.systems import BoucWen, Duffing, ShearBuilding

    gm = prepare("el_centro", dt=0.01, duration=25.0)
    hysteretic = ShearBuilding(5, storey_terms={2: {"term": "hysteresis", "beta": 5.0, "gamma": 5.0}})
    hysteretic.name = "5-storey shear building, hysteretic storey 2"
    out = []
    for system in (Duffing(), BoucWen(), ShearBuilding(), hysteretic):
        truth = system.true_values()
        row = {"system": system.name, "truth_ms": _best(lambda: simulate(system, truth, gm, gm.t), reps)}
        row["truth_ms_python"] = _best(lambda: simulate(system, truth, gm, gm.t, method="LSODA"), reps)
        rec = synthetic_from_motion(system, gm, noise=0.0, data_seed=0, params=truth)
        oe = ShootingProblem.from_rest(system, rec, 4)
        th = oe.pack(truth, np.zeros((1, system.n_state)))[: oe.n_theta]
        problem = build_problem(system, rec, RefineSettings(initial_state="free"))
        b = problem.bounds[:-1]
        states = np.hstack([rec.clean.x[b], rec.clean.v[b]] + ([rec.clean.z[b]] if system.n_latent else []))
        u = problem.pack(truth, states)
        y0 = np.zeros((1, system.n_state))
        for suffix, flag in (("", "1"), ("_python", "0")):
            os.environ["PIDYN_COMPILED"] = flag
            row["free_run_ms" + suffix] = _best(lambda: rk4(system, truth, gm.t, gm.acc, y0), reps)
            row["output_error_step_ms" + suffix] = _best(lambda: oe.residuals_and_fd_jacobian(th), reps)
            row["linearisation_ms" + suffix] = _best(lambda: problem.linearize(u), reps)
        os.environ.pop("PIDYN_COMPILED")
        out.append(row)
        print(row, flush=True)
    return out


def latent_path_ms(reps: int = 3) -> dict:
    """The diagnosis screening's latent states along a measured motion (``latent_path``): the
    Bouc-Wen effect's grid of shapes at once, and one shape, along 25 s of a Bouc-Wen response to
    El Centro at dt 0.01 s, in C and in Python (``PIDYN_COMPILED=0``), and their largest difference."""
    import os

    import numpy as np

    from pidyn.data.sources import synthetic_from_motion
    from pidyn.discrepancy.effects import Signals, get_effect
    from pidyn.excitation import prepare
    from pidyn.systems import BoucWen
    from pidyn.systems.terms import BoucWenHysteresis, latent_path

    gm = prepare("el_centro", dt=0.01, duration=25.0)
    rec = synthetic_from_motion(BoucWen(), gm)
    x = rec.x[:, 0]
    grid = get_effect("hysteresis")._grid(Signals(rec.t, x, rec.v[:, 0], 1.0, 12.0, "k", t_fit_end=16.0))
    term = BoucWenHysteresis(1.0, param="kh")
    cases = {
        f"grid of {len(grid)} shapes": {"beta": grid[:, 0], "gamma": grid[:, 1], "n": grid[:, 2]},
        "one shape": {"beta": 1.0, "gamma": 0.5, "n": 2.0},
    }
    out = {}
    for label, values in cases.items():
        fast = latent_path(term, rec.t, x, None, values)
        row = {"compiled_ms": _best(lambda: latent_path(term, rec.t, x, None, values), reps)}
        os.environ["PIDYN_COMPILED"] = "0"
        slow = latent_path(term, rec.t, x, None, values)
        row["python_ms"] = _best(lambda: latent_path(term, rec.t, x, None, values), 1)
        os.environ.pop("PIDYN_COMPILED")
        row["difference"] = float(np.nanmax(np.abs(fast - slow)) / max(np.nanmax(np.abs(slow)), 1e-300))
        out[label] = row
        print(label, row, flush=True)
    return out


def linear_map_ms(reps: int = 3) -> list[dict]:
    """A linear time-invariant model simulated with the exact sensitivities to every parameter
    (dual numbers, what an output-error fit does at each step), 25 s of El Centro at dt 0.01 s:
    by its RK4 scheme's one-sample map (``pidyn.integrate_linear``) and by the general loop,
    and the largest difference of the two as a share of the response."""
    import os

    import numpy as np

    from pidyn import integrate, integrate_linear
    from pidyn.autodiff import Dual
    from pidyn.excitation import prepare
    from pidyn.systems import LinearSDOF, ShearBuilding
    from pidyn.systems.sdof import SDOFSystem

    gm = prepare("el_centro", dt=0.01, duration=25.0)
    supports = SDOFSystem(LinearSDOF().terms, inputs=["s1", "s2", "s3"])
    shift = np.roll(gm.acc, 7)  # three supports: the record, delayed, and their velocities
    three = np.column_stack(
        [gm.acc, shift, 0.5 * gm.acc] + [np.cumsum(c) * 0.01 for c in (gm.acc, shift, 0.5 * gm.acc)]
    )
    out = []
    cases = (
        ("linear SDOF", LinearSDOF(), gm.acc),
        ("SDOF on three supports", supports, three),
        ("5-storey shear building", ShearBuilding(5), gm.acc),
    )
    for label, system, f in cases:
        names = [s.name for s in system.param_specs() if s.trainable]
        p = {s.name: float(s.init) for s in system.param_specs()}
        p.update({n: Dual(np.float64(p[n]), np.eye(len(names))[i]) for i, n in enumerate(names)})
        y0 = np.zeros((1, system.n_state))

        def run():
            return integrate.rk4(system, p, gm.t, f, y0)

        row = {"system": f"{label} ({len(names)} parameters)"}
        row["compiled_ms"] = _best(run, reps)
        compiled = run()[0]
        os.environ["PIDYN_COMPILED"] = "0"  # the one-sample map, then the loop in Python
        row["map_ms"] = _best(run, reps)
        fast = run()[0]
        general = integrate_linear.applies
        integrate_linear.applies = lambda *a, **k: False
        try:
            row["loop_ms"] = _best(run, reps)
            slow = run()[0]
        finally:
            integrate_linear.applies = general
            os.environ.pop("PIDYN_COMPILED")
        scale = np.abs(slow.v).max()
        row["difference"] = float(np.abs(fast.v - slow.v).max() / scale)
        row["compiled_difference"] = float(np.abs(compiled.v - slow.v).max() / scale)
        out.append(row)
        print(row, flush=True)
    return out


def _best(fn, reps: int) -> float:
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def lightning_overhead(n_iter: int = 1500, repeats: int = 3) -> dict:
    """Median over ``repeats`` alternating pairs, so that a load on the other core shifts both."""
    runs = [_overhead_once(n_iter) for _ in range(repeats)]
    plain = sorted(r["plain_s"] for r in runs)[len(runs) // 2]
    lit = sorted(r["lightning_s"] for r in runs)[len(runs) // 2]
    return {
        "iterations": n_iter,
        "plain_s": plain,
        "lightning_s": lit,
        "overhead_pct": 100 * (lit / plain - 1),
        "repeats": repeats,
        "pairs_pct": [round(r["overhead_pct"], 1) for r in runs],
    }


def _overhead_once(n_iter: int) -> dict:
    import lightning as L

    from pidyn.data.datamodule import SubperiodDataModule
    from pidyn.data.sources import synthetic
    from pidyn.models.lit_module import PIDynNetModule
    from pidyn.models.pidynnet import PIDynNet
    from pidyn.nets import TaylorMLP
    from pidyn.systems import Duffing

    torch.set_default_dtype(torch.float32)
    s = Duffing()
    rec = synthetic(s, "kobe", duration=12.0, dt=0.01)
    dm = SubperiodDataModule(rec, min_peak_fraction=0.0, accel_signal=s.excitation_as_acceleration(rec.f))

    def fresh():
        torch.manual_seed(0)
        mod = PIDynNetModule(PIDynNet(s, TaylorMLP()))
        mod.net.enter_window(dm.windows[3])
        mod.start(dm.windows[3], "identify", n_iter)
        return mod

    # plain loop: same module, same batches (with the excitation transform's q, q'), same
    # optimiser and schedule, the same parameter trajectory kept for the callbacks
    mod = fresh()
    dm.activate(3, n_iter, mod.inner_steps, True)
    (opt,), (sched,) = mod.configure_optimizers()
    batches = list(dm.train_dataloader())
    t0 = time.perf_counter()
    for b in batches:
        for k in range(b["t"].shape[0]):
            loss = mod.total(mod.losses(b["t"][k], b["f"][k], b["q"][k], b["qd"][k]))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            mod.trajectory.append(mod.net.params.raw_vector().detach().clone())
    plain = time.perf_counter() - t0

    mod = fresh()
    dm.activate(3, n_iter, mod.inner_steps, True)
    trainer = L.Trainer(
        accelerator="cpu",
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
    )
    t0 = time.perf_counter()
    trainer.fit(mod, datamodule=dm)
    lit = time.perf_counter() - t0
    return {
        "iterations": n_iter,
        "plain_s": plain,
        "lightning_s": lit,
        "overhead_pct": 100 * (lit / plain - 1),
    }


def end_to_end(args: list[str]) -> dict:
    run_dir = ROOT / "outputs" / "bench" / ("_".join(a.replace("=", "-") for a in args) or "default")
    cmd = [
        sys.executable,
        str(ROOT / "train.py"),
        *args,
        f"hydra.run.dir={run_dir}",
        "trainer.enable_progress_bar=false",
        "resume=false",
    ]
    if run_dir.exists():
        import shutil

        shutil.rmtree(run_dir)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    m = json.loads((run_dir / "metrics.json").read_text())
    return {
        "command": "python train.py " + " ".join(args),
        "wall_s": wall,
        "error_pct": m["error_pct"],
        "max_error_pct": m["max_error_pct"],
        "iterations": m["iterations"],
        "windows": m["windows"],
        "stage_seconds": m.get("stage_seconds", {}),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="skip end-to-end runs")
    ap.add_argument("--render", action="store_true", help="only write bench.md again from bench.json")
    ap.add_argument(
        "--simulation",
        action="store_true",
        help="only the simulation section, written into the last bench.json (its other rows kept)",
    )
    ap.add_argument(
        "--end-to-end",
        action="store_true",
        help="only the end-to-end runs, written into the last bench.json (its other rows kept)",
    )
    ap.add_argument(
        "--storey-cost", type=int, default=None, help=argparse.SUPPRESS
    )  # one size, in its own process
    a = ap.parse_args()
    if a.storey_cost is not None:
        torch.set_num_threads(1)
        print(json.dumps(storey_cost(a.storey_cost)))
        return
    if a.render:
        write_markdown(json.loads((OUT / "bench.json").read_text()))
        return
    torch.set_num_threads(1)
    if a.end_to_end or a.simulation:
        res = json.loads((OUT / "bench.json").read_text())
        (_end_to_end_section if a.end_to_end else _simulation_section)(res)
        (OUT / "bench.json").write_text(json.dumps(res, indent=2))
        write_markdown(res)
        return
    res: dict = {
        "command": "python experiments/bench.py" + (" --quick" if a.quick else ""),
        "machine": f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} thread, torch {torch.__version__}",
        "date": time.strftime("%Y-%m-%d"),
    }
    res["ms_per_iteration"] = {
        f"{mode}/{name}": per_iteration_ms(dt, mode)
        for mode in ("taylor", "autograd")
        for name, dt in (("float32", torch.float32), ("float64", torch.float64))
    }
    res["gpu_ms_per_iteration"] = gpu_ms()
    res["lightning_overhead"] = lightning_overhead()
    res["storeys"] = storey_scaling()
    res["simulation"] = simulation_ms()
    res["linear_map"] = linear_map_ms()
    res["latent_path"] = latent_path_ms()
    if not a.quick:
        res["end_to_end"] = [end_to_end([]), end_to_end(["system=bouc_wen"])]
    elif (OUT / "bench.json").exists():  # keep the last full run's end-to-end rows
        prev = json.loads((OUT / "bench.json").read_text())
        if "end_to_end" in prev:
            res["end_to_end"] = prev["end_to_end"]
            res["end_to_end_date"] = prev.get("end_to_end_date") or prev.get("date", "")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench.json").write_text(json.dumps(res, indent=2))
    write_markdown(res)


def _end_to_end_section(res: dict) -> None:
    """The end-to-end runs measured again (``--end-to-end``), into the last full run's results."""
    res["end_to_end"] = [end_to_end([]), end_to_end(["system=bouc_wen"])]
    res["end_to_end_date"] = time.strftime("%Y-%m-%d")


def _simulation_section(res: dict) -> None:
    """The simulation section measured again (``--simulation``), into the last full run's results."""
    res["simulation"] = simulation_ms()
    res["linear_map"] = linear_map_ms()
    res["latent_path"] = latent_path_ms()
    res["simulation_date"] = time.strftime("%Y-%m-%d")
    # the machine may not be the one of the other rows: its taylor/float32 iteration, to compare
    res["simulation_reference_ms"] = per_iteration_ms(torch.float32, "taylor")


def write_markdown(res: dict) -> None:
    lines = [
        f"# Benchmark\n\nCommand: `{res['command']}`  \nMachine: {res['machine']}  \nDate: {res['date']}\n",
        "## ms per training iteration (500 collocation points, x, x', x'', plus data loss)\n",
        "| derivatives | ms |",
        "|---|---|",
    ]
    lines += [f"| {k} | {v:.2f} |" for k, v in res["ms_per_iteration"].items()]
    lines += _gpu_lines(res) + _overhead_lines(res) + _simulation_lines(res) + _end_to_end_lines(res)
    real = OUT / "bench_real.md"  # experiments/bench_real.py: the Painter Street events side by side
    if real.exists():
        lines += ["", real.read_text().rstrip()]
    (OUT / "bench.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _gpu_lines(res: dict) -> list[str]:
    lines: list[str] = []
    gpu = res.get("gpu_ms_per_iteration") or {"device": None}
    if gpu["device"]:
        lines += [
            "",
            f"## The same steps on the GPU ({gpu['device']}), beside one CPU thread\n",
            "| step | GPU ms | CPU ms |",
            "|---|---|---|",
        ]
        cpu = {
            **res["ms_per_iteration"],
            **{f"storeys/{r['storeys']}": r["ms_per_iteration"] for r in res.get("storeys", [])},
        }
        lines += [
            f"| {k} | {v:.2f} | {cpu.get(k, float('nan')):.2f} |" for k, v in gpu.items() if k != "device"
        ]
    else:
        lines += [
            "",
            "GPU: none on this machine (`make bench` adds GPU rows where `torch.cuda.is_available()`).",
        ]
    return lines


def _overhead_lines(res: dict) -> list[str]:
    lines: list[str] = []
    lo = res["lightning_overhead"]
    lines += [
        "",
        "## Lightning against a plain loop (same module, same batches)\n",
        f"{lo['iterations']} iterations: plain {lo['plain_s']:.2f} s, Lightning {lo['lightning_s']:.2f} s, "
        f"overhead {lo['overhead_pct']:+.1f} % (medians of {lo.get('repeats', 1)} alternating runs; "
        f"each pair: {lo.get('pairs_pct', [])} %)",
    ]
    lines += [
        "",
        "## Shear buildings: cost against the number of storeys (accelerometers on every floor, "
        "El Centro 20 s)\n",
        "| storeys | refinement unknowns (1 s segments) | PIDynNet ms / iteration | refinement ms / "
        "linearisation (residuals + exact Jacobian) | peak memory MB |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['storeys']} | {r['unknowns']} | {r['ms_per_iteration']:.1f} | {r['ms_per_linearisation']:.0f} | "
        f"{r['peak_rss_mb']:.0f} |"
        for r in res["storeys"]
    ]
    return lines


def _simulation_lines(res: dict) -> list[str]:
    lines: list[str] = []
    if "simulation" in res:
        when = (
            f", measured {res['simulation_date']} by `python experiments/bench.py --simulation`"
            if res.get("simulation_date")
            else ""
        )
        if res.get("simulation_reference_ms"):
            when += (
                f" on a machine where the taylor/float32 iteration above took "
                f"{res['simulation_reference_ms']:.2f} ms"
            )
        lines += [
            "",
            f"## Simulation (El Centro 25 s at dt 0.01 s, RK4 with 4 substeps; best of 3{when})\n",
            "Each cell: the compiled loop (`pidyn.compiled`, the default where a C compiler is found) / "
            "the loop in Python (`PIDYN_COMPILED=0`). The first use of a model compiles it once "
            "(0.1-1 s, kept on disk).\n",
            "The ground truth: Dormand and Prince's pair in C (`pidyn.simulate`'s default) / LSODA "
            '(`method="LSODA"`), both at rtol 1e-10.\n',
            "| system | ground truth ms | free run ms | output-error step (residuals + FD Jacobian) ms | "
            "refinement linearisation (residuals + exact Jacobian, 1 s segments) ms |",
            "|---|---|---|---|---|",
        ]

        def pair(r: dict, key: str) -> str:
            if key + "_python" not in r:
                return f"{r[key]:.0f}" if key in r else "-"
            return f"{r[key]:.1f} / {r[key + '_python']:.0f}"

        lines += [
            f"| {r['system']} | {pair(r, 'truth_ms')} | {pair(r, 'free_run_ms')} | "
            f"{pair(r, 'output_error_step_ms')} | {pair(r, 'linearisation_ms')} |"
            for r in res["simulation"]
        ]
    if "linear_map" in res:
        lines += [
            "",
            "### Linear models: the compiled loop, the RK4 scheme's one-sample map and the loop in Python\n",
            "The same scheme and the same sensitivities (25 s, exact Jacobian to every parameter by dual numbers, "
            "what an output-error fit does at each step); the differences are the largest from the loop in Python, "
            "as a share of the response. The compiled loop is the default; the map stands in where there is no "
            "C compiler.\n",
            "| system | compiled loop ms | one-sample map ms | loop in Python ms | difference: compiled, map |",
            "|---|---|---|---|---|",
        ]
        lines += [
            f"| {r['system']} | {r['compiled_ms']:.1f} | {r['map_ms']:.1f} | {r['loop_ms']:.0f} | "
            f"{r['compiled_difference']:.1e}, {r['difference']:.1e} |"
            if "compiled_ms" in r
            else f"| {r['system']} | - | {r['map_ms']:.1f} | {r['loop_ms']:.0f} | -, {r['difference']:.1e} |"
            for r in res["linear_map"]
        ]
    return lines + _latent_path_lines(res)


def _latent_path_lines(res: dict) -> list[str]:
    if "latent_path" not in res:
        return []
    lines = [
        "",
        "### The screening's latent paths: in C and in Python\n",
        "The Bouc-Wen effect's latent state along 25 s of a measured motion (`latent_path`: Heun's rule "
        "along the displacement, what the diagnosis screens every hysteretic and elastoplastic shape "
        "with); the difference is the largest, as a share of the state.\n",
        "| case | compiled ms | Python ms | difference |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {k} | {r['compiled_ms']:.1f} | {r['python_ms']:.0f} | {r['difference']:.1e} |"
        for k, r in res["latent_path"].items()
    ]
    return lines


def _end_to_end_lines(res: dict) -> list[str]:
    lines: list[str] = []
    if "end_to_end" in res:
        lines += [
            "",
            "## End to end"
            + (f" (measured {res['end_to_end_date']})" if res.get("end_to_end_date") else "")
            + "\n",
            "| command | wall s | windows | iterations | errors % | s by stage (metrics.json's stage_seconds) |",
            "|---|---|---|---|---|---|",
        ]
        for e in res["end_to_end"]:
            errs = ", ".join(f"{k} {v:.2g}" for k, v in e["error_pct"].items())
            stages = ", ".join(f"{k} {v:.1f}" for k, v in e.get("stage_seconds", {}).items()) or "-"
            lines.append(
                f"| `{e['command']}` | {e['wall_s']:.0f} | {e['windows']} | {e['iterations']} | {errs} | {stages} |"
            )
    return lines


if __name__ == "__main__":
    main()
