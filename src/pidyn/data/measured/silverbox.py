"""The Silverbox benchmark (Wigren and Schoukens 2013): a measured electronic Duffing oscillator.

Input V1 (V) is the "force" u, output V2 (V) the "displacement" x; fs = 10^7 / 2^14 Hz. Only
ratios of the model's coefficients are identifiable from u -> x, so the mass (the
coefficient of x'') is identified along with the others. The multisine part is split as the
benchmark splits it, test [105712, 127400) (0-based samples), with the estimation part
[40540, 105712) starting in the quiet gap before the first multisine realisation (samples
40519-40561 stay within 3 mV), 110 samples before the benchmark's 40650: a model simulated
from rest then starts where the circuit is at rest (from 40650 its first 0.3 s miss by 20 mV).
"""

from __future__ import annotations

from importlib import resources

import numpy as np
from scipy.io import loadmat

from pidyn.data.meta import RecordMeta, Split
from pidyn.data.sources import DataError, Record

FS = 1e7 / 2**14
ESTIMATION = (40540, 105712)
TEST = (105712, 127400)


def load_silverbox(
    estimation: tuple[int, int] = ESTIMATION,
    test: tuple[int, int] = TEST,
) -> Record:
    """The estimation and test parts as one record (time 0 at the first estimation sample).

    ``meta.split`` holds the fitting and held-out time spans; the offsets of V1 and V2
    (measurement offsets, as the official README notes) are removed using the estimation part.
    """
    ref = resources.files("pidyn.data.measured").joinpath("silverbox/SNLS80mV.mat")
    with resources.as_file(ref) as path:
        try:
            mat = loadmat(path)
        except Exception as exc:  # scipy raises several types for damaged files
            raise DataError(f"{path}: cannot be read as a MATLAB file ({exc})") from None
    u, y = np.ravel(mat["V1"]).astype(float), np.ravel(mat["V2"]).astype(float)
    lo, hi = estimation[0], test[1]
    if not (0 <= lo < estimation[1] <= test[0] < hi <= len(u)):
        raise DataError(
            f"silverbox: bad sample ranges estimation={estimation}, test={test} (record has {len(u)})"
        )
    e = slice(*estimation)
    u = u - u[e].mean()
    y = y - y[e].mean()
    t = np.arange(hi - lo) / FS
    fit_end = (estimation[1] - 1 - lo) / FS
    return Record(
        name="silverbox_SNLS80mV",
        t=t,
        f=u[lo:hi],
        x=y[lo:hi],
        excitation="force",
        meta=RecordMeta(
            dt=1 / FS,
            fs=FS,
            units={"x": "V", "u": "V"},
            # the input was low-pass filtered before sampling, at 9 samples a period of the
            # resonance: read between samples band-limited, not linear (see pidyn.integrate)
            input_hold="bandlimited",
            split=Split((0.0, fit_end), ((test[0] - lo) / FS, (test[1] - 1 - lo) / FS)),
            source="Silverbox SNLS80mV (Wigren & Schoukens 2013)",
        ),
    )
