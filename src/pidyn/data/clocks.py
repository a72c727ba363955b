"""Film records' recorders put on one clock.

A film-era station ran several recorders, each on its own clock (Painter Street: channels 1-8 on
one, 9-20 on another). The V2 headers give each recorder's trigger time to 0.1 s only, so two
recorders may be a few samples apart. Against a 0.25 s bridge, 0.05 s is a fifth of a period:
a deck channel on one recorder then answers a support motion on the other before it arrives.

The offset is read from the supports' own ground motions, not from the structure's response
(which a prediction must not see): below a few Hz, ground motions a bridge's length apart move
together, so their cross-correlation peaks where the clocks agree. Pairs on either side of a
middle support cancel the wave's passage to first order; what is left of it cannot be told from
a clock offset, and the note says so with the number.

Only an offset of at least one sample is corrected. Below it the estimate is no firmer than
its errors: on Painter Street's single-clock digital records it reads -0.003 to +0.007 s where
the truth is zero, and on the film records it moves by up to 0.02 s with the band compared
(and a deck channel pair's own low band can disagree by as much)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pidyn.notes import note
from pidyn.signals import lagged_correlation, peak_fraction

#: band (Hz) in which the supports' ground motions are compared: long waves, coherent along a
#: bridge, and below the structure's own frequency even where strong shaking softens it (Painter
#: Street: 2.2-2.5 Hz in the 1992 main shock), whose response a support's base also carries
BAND_HZ = (0.2, 1.5)
#: the largest offset looked for (s): the headers' trigger times are given to 0.1 s
MAX_LAG_S = 0.2
#: below this correlation of the supports' ground motions the offset is not trusted
MIN_CORRELATION = 0.7


@dataclass(frozen=True)
class Offset:
    """A recorder's clock against the reference recorder's: its samples are ``seconds`` late
    (negative: early), read from ``pairs`` of ground channels that correlate at ``r``."""

    recorder: str
    seconds: float
    r: float
    pairs: tuple[tuple[int, int], ...]


def reference_recorder(archive) -> str:
    """The recorder that holds the most channels (ties: the first by name): the others move to it."""
    counts: dict[str, int] = {}
    for ch in archive.channels.values():
        counts[ch.recorder] = counts.get(ch.recorder, 0) + 1
    return sorted(counts, key=lambda r: (-counts[r], r))[0]


def recorder_offsets(
    archive, groups: Sequence[Sequence[int]], used: Sequence[int] | None = None
) -> tuple[list[Offset], list[str]]:
    """The offset against the reference of each further recorder that holds a ``used`` channel
    (default: any), from the ground channels of each group (a direction's supports) that lie on
    different recorders; with the notes that say it."""
    chans = archive.channels
    used = list(chans) if used is None else [c for c in used if c in chans]
    recorders = {chans[c].recorder for c in used} | {
        chans[c].recorder for g in groups for c in g if c in chans
    }
    if len(recorders) < 2 or "" in recorders:
        return [], []
    ref = reference_recorder(archive)
    offsets, notes = [], []
    for rec in sorted({chans[c].recorder for c in used} - {ref}):
        pairs = [
            (i, j)
            for g in groups
            for i in g
            for j in g
            if i in chans and j in chans and chans[i].recorder == rec and chans[j].recorder == ref
        ]
        if not pairs:
            notes.append(
                note(
                    "recorders_not_aligned",
                    f"recorder {rec}: none of its channels is a support's ground motion; its clock is "
                    f"taken as recorder {ref}'s",
                )
            )
            continue
        off = _pair_offset(archive, rec, pairs)
        refused = _refusal(off, ref, archive.channels[pairs[0][0]].dt)
        if refused:
            notes.append(refused)
            continue
        offsets.append(off)
        notes.append(
            note(
                "recorders_aligned",
                f"recorder {rec} reads {abs(off.seconds):.3f} s {'late' if off.seconds > 0 else 'early'} "
                f"against {ref} (ground channels {_pairs_text(pairs)}, r={off.r:.2f}; the wave's passage "
                f"between them cannot be told from it): its channels are shifted onto {ref}'s clock",
            )
        )
    return offsets, notes


def _refusal(off: Offset, ref: str, step: float) -> str | None:
    """Why an offset is not used (a note), or None: the ground channels correlate too weakly, the
    peak lies at the end of the lags looked at, or it is less than a sample."""
    said = f"recorder {off.recorder} against {ref}: ground channels {_pairs_text(off.pairs)}"
    if off.r < MIN_CORRELATION or abs(off.seconds) >= MAX_LAG_S:
        why = f"correlate at r={off.r:.2f} (lag {off.seconds:+.3f} s); its clock is taken as {ref}'s"
        return note("recorders_not_aligned", f"{said} {why}")
    if abs(off.seconds) < step:
        why = (
            f"read {off.seconds:+.3f} s (r={off.r:.2f}): less than a sample ({step:g} s), no more than the "
            "wave's passage and the band chosen move the estimate; left on its own clock"
        )
        return note("recorders_not_aligned", f"{said} {why}")
    return None


def _pairs_text(pairs: Sequence[tuple[int, int]]) -> str:
    return ", ".join(f"{i}-{j}" for i, j in pairs)


def _pair_offset(archive, rec: str, pairs: Sequence[tuple[int, int]]) -> Offset:
    """The lag at which the pairs' summed normalised cross-correlation peaks, to a fraction of a
    sample (``pidyn.signals``: the same low-band correlation that times an IMU floor)."""
    chans = archive.channels
    dt = chans[pairs[0][0]].dt
    total = sum(lagged_correlation(chans[i].acc, chans[j].acc, dt, MAX_LAG_S, BAND_HZ) for i, j in pairs)
    total = total / len(pairs)
    m = (len(total) - 1) // 2
    k = int(np.argmax(total))
    # peak at lag L > 0: the reference's channel follows this recorder's by L, so this one is early
    return Offset(rec, -(k - m + peak_fraction(total, k)) * dt, float(total[k]), tuple(pairs))


def shifted(y: np.ndarray, seconds: float, dt: float) -> np.ndarray:
    """``y`` delayed by ``seconds`` (negative: advanced), to a fraction of a sample: a phase shift
    on a zero-padded grid, so nothing wraps round; the samples moved in from outside are zero."""
    y = np.asarray(y, float)
    n = len(y)
    f = np.fft.rfftfreq(2 * n, dt)
    out = np.fft.irfft(np.fft.rfft(y, 2 * n) * np.exp(-2j * np.pi * f * seconds), 2 * n)[:n]
    return out
