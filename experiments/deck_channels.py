"""What a bridge's deck channels say of a rigid deck, before any model is fitted.

For every readable event of a station's transverse set, the deck channels at the deck's two ends
give the straight line a rigid deck moves on; the channel between them (over a bent) is compared
with that line at the layout's position and at others. The table says how much of the middle
channel no rigid deck can explain, and which of two span orders (which span is the west one) the
data prefer.

    python experiments/deck_channels.py                      # Painter Street (CE89324)
    python experiments/deck_channels.py --swap 36.3          # the other span order's bent position

Writes experiments/results/real/deck_channels_<station>.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pidyn.data.layout import station_deck
from pidyn.data.strong_motion import csmip_record

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results" / "real"


def middle_and_ends(deck, rec) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """The channel between the ends and the two end channels (ordered first end, last end)."""
    chans = list(rec.meta.sensor_channels)
    pos = [deck.sensors[f"ch{c}"] for c in chans]
    raw = np.asarray(rec.meta.sensor_a)
    first, last = int(np.argmin(pos)), int(np.argmax(pos))
    mid = next(i for i in range(len(chans)) if i not in (first, last))
    return raw[:, mid], raw[:, first], raw[:, last], f"ch{chans[mid]}"


def residual_share(mid: np.ndarray, a: np.ndarray, b: np.ndarray, xi: float) -> float:
    """RMS of the middle channel off the line through the ends at fraction ``xi``, over its own RMS."""
    return float(np.std(mid - ((1 - xi) * a + xi * b)) / np.std(mid))


def best_position(mid: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """The fraction of the length at which the line through the ends best matches the middle channel."""
    d = b - a
    return float(d @ (mid - a) / (d @ d))


def rows(records: Path, station: str, swap: float) -> list[dict]:
    deck = station_deck(station, "transverse")
    out = []
    for path in sorted(records.glob("*.zip")):
        try:
            rec = csmip_record(path, station=station, direction="transverse", system=deck)
        except (ValueError, FileNotFoundError) as exc:
            out.append({"event": path.name, "error": str(exc).splitlines()[0]})
            continue
        mid, a, b, name = middle_and_ends(deck, rec)
        xi = deck.sensors[name] / deck.length
        out.append(
            {
                "event": path.name.split("_ce")[0],
                "pga_g": float(rec.meta.pga) / 9.80665,
                "channel": name,
                "layout": residual_share(mid, a, b, xi),
                "swapped": residual_share(mid, a, b, swap / deck.length),
                "best_xi": best_position(mid, a, b),
                "layout_xi": xi,
            }
        )
    return out


def markdown(lines: list[dict], station: str, swap: float) -> str:
    ok = [r for r in lines if "error" not in r]
    better = sum(r["layout"] < r["swapped"] - 1e-3 for r in ok)
    tie = sum(abs(r["layout"] - r["swapped"]) <= 1e-3 for r in ok)
    strong = [r["layout"] for r in ok if r["pga_g"] >= 0.2]
    weak = [r["layout"] for r in ok if r["pga_g"] < 0.2]
    out = [
        f"# The deck channels of {station} against a rigid deck",
        "",
        f"`python experiments/deck_channels.py --station {station} --swap {swap:g}`. For every readable event, "
        "the middle deck channel's RMS off the straight line through the two end channels, as a share of its "
        "own RMS (0: a rigid deck explains it; 1: nothing of it), at the layout's position, at the other span "
        "order's, and the position that fits best (fraction of the length from the first end).",
        "",
        f"- the layout's position fits better than {swap:g} m in {better} of {len(ok)} events ({tie} within 0.001)",
        f"- unexplained share at the layout's position: {_range(strong)} in the strong events (PGA >= 0.2 g), "
        f"{_range(weak)} in the others",
        "",
        "| event | PGA (g) | channel | unexplained, layout | unexplained, other order | best position | layout |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in sorted(ok, key=lambda r: -r["pga_g"]):
        out.append(
            f"| {r['event']} | {r['pga_g']:.3f} | {r['channel']} | {r['layout']:.3f} | {r['swapped']:.3f} | "
            f"{r['best_xi']:.2f} | {r['layout_xi']:.2f} |"
        )
    for r in lines:
        if "error" in r:
            out.append(f"| {r['event']} | - | - | not read: {r['error']} | | | |")
    return "\n".join(out) + "\n"


def _range(values: list[float]) -> str:
    return f"{min(values):.2f}-{max(values):.2f}" if values else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--station", default="CE89324")
    ap.add_argument("--records", type=Path, default=ROOT / "data" / "painter_street" / "records")
    ap.add_argument(
        "--swap", type=float, default=36.3, help="the bent's position (m) in the other span order"
    )
    args = ap.parse_args()
    text = markdown(rows(args.records, args.station, args.swap), args.station, args.swap)
    path = RESULTS / f"deck_channels_{args.station.lower()}.md"
    path.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
