"""One BLAS thread for pidyn's commands, set on import, before NumPy and SciPy load their BLAS.

Their matrices are small (a Jacobian of a few thousand rows by tens of columns), so a second
BLAS thread gains nothing; but it spins between calls, and on two cores it takes the core that
the baselines' worker, or a compiled integration's second thread, would use. Measured on a
Painter Street identification: the refinement's period scan and profile took 3.7 s with
OpenBLAS's default threads and 2.2 s with one. A value the user sets is kept.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
