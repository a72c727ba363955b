"""The diagnosis's figures: the simulated response against the measured one, the residual force
and what explains it, the screening's ranking, the running estimate and period, and a learned
force's surface."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.signal import welch

from pidyn.discrepancy.evidence import Evidence
from pidyn.reporting import plottable, pyplot


def _plt():
    plt = pyplot()

    return plt


def _shade(ax, fit, held) -> None:
    ax.axvspan(*held, color="0.92", zorder=0, label="held out")


def plot_response(
    path: Path, t, x, x_nom, x_ext, fit, held, unit: str = "m", period: float | None = None
) -> None:
    """Measured vs simulated displacement (nominal, extended) and the simulation errors; for a
    record of many periods, a third panel zooms into 30 periods at the start of the held-out part."""
    plt = _plt()
    x_nom = plottable(x_nom)  # a model that blows up is drawn up to the blow-up
    x_ext = None if x_ext is None else plottable(x_ext)
    zoom = period is not None and (t[-1] - t[0]) > 200 * period
    fig, axes = plt.subplots(3 if zoom else 2, 1, figsize=(11, 8 if zoom else 5.5))
    a1, a2 = axes[0], axes[1]
    a2.sharex(a1)
    if zoom:
        a3 = axes[2]
        sel = (t >= held[0]) & (t <= held[0] + 30 * period)
        a3.plot(t[sel], x[sel], color="k", lw=0.8, label="measured")
        a3.plot(t[sel], x_nom[sel], color="tab:red", lw=0.8, label="nominal model")
        if x_ext is not None:
            a3.plot(t[sel], x_ext[sel], color="tab:blue", lw=0.8, ls="--", label="extended model")
        a3.set(xlabel="t [s]", ylabel=f"x [{unit}]", title="zoom: start of the held-out part")
        a3.legend(loc="upper right", fontsize=8, ncol=3)
    _shade(a1, fit, held)
    a1.plot(t, x, color="k", lw=0.6, label="measured")
    a1.plot(t, x_nom, color="tab:red", lw=0.7, label="nominal model")
    if x_ext is not None:
        a1.plot(t, x_ext, color="tab:blue", lw=0.7, ls="--", label="extended model")
    a1.set_ylabel(f"x [{unit}]")
    a1.legend(loc="upper right", fontsize=8, ncol=4)
    _shade(a2, fit, held)
    a2.plot(t, x_nom - x, color="tab:red", lw=0.6, label="nominal - measured")
    if x_ext is not None:
        a2.plot(t, x_ext - x, color="tab:blue", lw=0.6, label="extended - measured")
    a2.set_ylabel(f"error [{unit}]")
    a2.set_xlabel("t [s]")
    a2.legend(loc="upper right", fontsize=8)
    fig.suptitle("What the simulation gets wrong: free simulation from the measured initial state")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_residual(path: Path, t, r_raw, x, v, fit, cause, fitted, units: dict, period: float) -> None:
    """The force the nominal model cannot explain: over time, against x and x', spectrum.

    The residual and x, x' are band-limited alike (``residual.unexplained_force``); one
    natural period at each end, where the spectral derivative rings, is left out."""
    plt = _plt()
    dt = float(t[1] - t[0])
    edge = max(1, int(round(period / dt)))
    if len(r_raw) > 4 * edge:
        inner = slice(edge, len(r_raw) - edge)
        t, r_raw, x, v = t[inner], r_raw[inner], x[inner], v[inner]
        fitted = None if fitted is None else fitted[inner]
    r = r_raw
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    ux, uf = units.get("x", "m"), units.get("u", "N")
    ax[0, 0].plot(t, r, lw=0.4, color="0.2", label="unexplained force")
    if fitted is not None:
        ax[0, 0].plot(t, fitted, lw=0.6, color="tab:blue", label=f"explained by {cause}")
    ax[0, 0].axvline(fit[1], color="k", ls=":", lw=0.8)
    ax[0, 0].set(xlabel="t [s]", ylabel=f"force [{uf}]", title="over time (dotted: end of fitting part)")
    ax[0, 0].legend(fontsize=8)
    step = max(1, len(t) // 20000)
    for a, s, lab in ((ax[0, 1], x, f"x [{ux}]"), (ax[1, 0], v, f"x' [{ux}/s]")):
        a.scatter(s[::step], r[::step], s=1, c=t[::step], cmap="viridis", alpha=0.5, rasterized=True)
        if fitted is not None:
            a.scatter(
                s[::step],
                fitted[::step],
                s=0.5,
                color="tab:red",
                alpha=0.5,
                rasterized=True,
                label=f"explained by {cause}",
            )
            a.legend(fontsize=8, markerscale=8)
        a.set(xlabel=lab, ylabel=f"force [{uf}]", title=f"against {lab.split()[0]} (colour: time)")
    nper = int(min(len(r), 2048))
    f, pr = welch(r_raw - r_raw.mean(), fs=1 / dt, nperseg=nper)
    ax[1, 1].semilogy(f[1:], pr[1:], color="0.3", lw=0.8, label="unexplained force")
    if fitted is not None:
        _, pf = welch(fitted - fitted.mean(), fs=1 / dt, nperseg=nper)
        ax[1, 1].semilogy(f[1:], pf[1:], color="tab:blue", lw=0.8, label=f"explained by {cause}")
    ax[1, 1].set(xlabel="frequency [Hz]", ylabel="PSD", title="spectrum")
    ax[1, 1].legend(fontsize=8)
    fig.suptitle("The force the nominal model cannot explain")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_ranking(path: Path, ranking: list[Evidence], min_delta_bic: float) -> None:
    plt = _plt()
    rows = [r for r in ranking if r.score is not None]
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.2))
    names = [r.effect for r in rows][::-1]
    scores = [r.score for r in rows][::-1]
    colors = ["tab:blue" if r.passes else "0.6" for r in rows][::-1]
    ax.barh(names, scores, color=colors)
    ax.axvline(
        min_delta_bic, color="k", ls=":", lw=0.8, label=f"evidence threshold (-dBIC = {min_delta_bic:g})"
    )
    ax.set_xscale("symlog")
    ax.set_xlabel("score = -dBIC (symlog)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_running_estimate(
    path: Path,
    running: dict,
    nominal: dict,
    fit,
    held,
    change=None,
    stiffness: str | None = None,
    signal: tuple | None = None,
) -> None:
    """The nominal parameters refitted in sliding windows over the record, relative to the
    nominal fit: a change in time shows as a step, located with its interval when found. With
    the ``stiffness`` parameter named, a second panel gives the running natural period
    2 pi sqrt(m / k(t)) (and the damping ratio) beside the motion's envelope (``signal``: t, x),
    so a period that lengthens in the strong motion and recovers in the coda shows as such."""
    plt = _plt()
    names = [n for n in running if n != "t" and n in nominal and n != "m"]
    with_period = stiffness is not None and stiffness in running and nominal.get(stiffness, 0) > 0
    fig, axes = plt.subplots(
        2 if with_period else 1, 1, figsize=(10, 6.8 if with_period else 3.8), squeeze=False
    )
    ax = axes[0, 0]
    _shade(ax, fit, held)
    for n in names:
        ax.plot(
            running["t"], np.asarray(running[n]) / nominal[n], marker=".", lw=1, label=f"{n} / nominal {n}"
        )
    ax.axhline(1.0, color="k", lw=0.6)
    if change is not None:
        ax.axvspan(*change.ci95, color="tab:orange", alpha=0.25, label="change, 95 % interval")
        ax.axvline(change.t_change, color="tab:orange", lw=1.2)
        ax.axhline(
            1.0 + change.fraction,
            color="tab:orange",
            lw=0.8,
            ls="--",
            label=f"{change.parameter} after the change ({100 * change.fraction:+.0f} %)",
        )
    ax.set(
        xlabel="t [s] (window centre)",
        ylabel="running estimate / nominal",
        title="Running estimate over the record (sliding weak-form fit)",
    )
    ax.legend(fontsize=8, loc="best")
    if with_period:
        _period_panel(axes[1, 0], running, nominal, fit, held, stiffness, signal)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _period_panel(a2, running: dict, nominal: dict, fit, held, stiffness: str, signal: tuple | None) -> None:
    """The running natural period (and damping ratio) beside the motion's envelope."""
    m = float(nominal.get("m", 1.0))
    k = np.asarray(running[stiffness], float)
    period = np.where(k > 0, 2 * np.pi * np.sqrt(m / np.where(k > 0, k, 1.0)), np.nan)
    _shade(a2, fit, held)
    a2.plot(running["t"], period, marker=".", lw=1.2, color="tab:blue", label="running period")
    a2.axhline(
        2 * np.pi * np.sqrt(m / nominal[stiffness]),
        color="tab:blue",
        lw=0.7,
        ls="--",
        label="nominal model's period",
    )
    a2.set(xlabel="t [s] (window centre)", ylabel="period [s]", title="Natural period through the record")
    if signal is not None:
        b = a2.twinx()
        b.plot(signal[0], np.abs(signal[1]), color="0.6", lw=0.5, zorder=0)
        b.set_ylabel("|x| (relative displacement)", color="0.5")
    if "c" in running and nominal.get("c") is not None:
        c = np.asarray(running["c"], float)
        zeta = np.where(k > 0, c / (2 * np.sqrt(m * np.where(k > 0, k, 1.0))), np.nan)
        a2.plot([], [], color="tab:red", marker=".", label="damping ratio (right axis, x100 %)")
        z = a2.twinx()
        z.spines["right"].set_position(("axes", 1.08))
        z.plot(running["t"], 100 * zeta, marker=".", lw=0.8, color="tab:red")
        z.set_ylabel("damping ratio [%]", color="tab:red")
    a2.legend(fontsize=8, loc="upper right")


def plot_learned_force(path: Path, x, v, residual, learned, surface: dict, units: dict) -> None:
    """The learned force beside the force the nominal model could not explain: against x and x'
    (the loops a structural engineer reads), and the learned f(x, x') as a surface."""
    plt = _plt()
    ux, uf = units.get("x", "m"), units.get("u", "N")
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    step = max(1, len(x) // 20000)
    for a, sig, lab in ((ax[0], x, f"x [{ux}]"), (ax[1], v, f"x' [{ux}/s]")):
        a.scatter(
            sig[::step],
            residual[::step],
            s=1,
            color="0.6",
            alpha=0.5,
            rasterized=True,
            label="unexplained force",
        )
        a.scatter(
            sig[::step],
            learned[::step],
            s=1,
            color="tab:blue",
            alpha=0.6,
            rasterized=True,
            label="learned force",
        )
        a.set(xlabel=lab, ylabel=f"force [{uf}]")
        a.legend(fontsize=8, markerscale=8)
    cs = ax[2].contourf(surface["x"], surface["v"], surface["f"], levels=20, cmap="RdBu_r")
    ax[2].plot(x[::step], v[::step], color="k", lw=0.2, alpha=0.4)
    ax[2].set(xlabel=f"x [{ux}]", ylabel=f"x' [{ux}/s]", title="learned f(x, x') (line: the record's path)")
    fig.colorbar(cs, ax=ax[2], label=f"force [{uf}]")
    fig.suptitle("Learned force (universal differential equation) against the unexplained force")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_running_period(
    path: Path,
    running: dict,
    fit,
    held,
    signal: tuple | None = None,
    nominal_period: float | None = None,
    model: tuple | None = None,
) -> None:
    """Period and damping ratio window by window (output error on the sensors' readings), each with
    its 95 % interval, over the motion's envelope; ``model`` (t, period, zeta): an
    amplitude-dependent model's own, along its simulated response."""
    plt = _plt()
    t = np.asarray(running["t"])
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    for ax, key, label, scale in (
        (axes[0], "period", "period [s]", 1.0),
        (axes[1], "damping", "damping ratio [%]", 100.0),
    ):
        _shade(ax, fit, held)
        ax.fill_between(
            t,
            scale * np.asarray(running[f"{key}_lo"]),
            scale * np.asarray(running[f"{key}_hi"]),
            color="tab:blue",
            alpha=0.25,
            label="95 % interval",
        )
        ax.plot(
            t, scale * np.asarray(running[key]), marker=".", color="tab:blue", lw=1.2, label=f"running {key}"
        )
        ax.set_ylabel(label)
        if signal is not None:
            b = ax.twinx()
            b.plot(signal[0], np.abs(signal[1]), color="0.65", lw=0.5, zorder=0)
            b.set_ylabel("|measured| (sensor)", color="0.5")
    if nominal_period is not None:
        axes[0].axhline(nominal_period, color="k", lw=0.7, ls="--", label="one model for the fitting part")
    if model is not None:
        label = "amplitude-dependent model (its own response's envelope)"
        axes[0].plot(model[0], model[1], color="tab:red", lw=1.0, label=label)
        axes[1].plot(model[0], 100.0 * np.asarray(model[2]), color="tab:red", lw=1.0)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[0].set_title("Natural period and damping through the record (windows fitted by output error)")
    axes[1].set_xlabel("t [s] (window centre)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
