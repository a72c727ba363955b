"""The screening's regressions: least squares on unit-norm columns (a ridge where a basis is
flexible), a candidate's fit on the fitting part scored on the held-out part, and the blocked
cross-validation that says whether a column predicts rows it was not fitted on."""

from __future__ import annotations

import numpy as np

from pidyn.discrepancy.effects import Candidate


def lstsq(
    A: np.ndarray, y: np.ndarray, ridge: np.ndarray | None = None, scale: np.ndarray | None = None
) -> np.ndarray:
    """Least squares on unit-norm columns; ``ridge`` (per column, on that scale) damps the
    columns of a flexible basis so that near-collinear ones cannot take huge opposite values.
    ``scale``: fixed column scales (the whole record's), so that a column nearly silent in a
    cross-validation training block is not blown up to unit norm there."""
    if scale is None:
        scale = np.sqrt((A**2).sum(0))
    scale = np.where(scale == 0, 1.0, scale)
    As = A / scale
    if ridge is None:
        sol, *_ = np.linalg.lstsq(As, y, rcond=None)
    else:
        # the ridge as extra rows: the same solution, and a column silent in these rows (a stop
        # never reached in the fitting part) leaves it rank deficient instead of singular
        aug = np.vstack([As, np.diag(np.sqrt(ridge))])
        sol, *_ = np.linalg.lstsq(aug, np.r_[y, np.zeros(len(ridge))], rcond=None)
    return sol / scale


def _folds(fit: np.ndarray, k: int) -> list[np.ndarray]:
    """k contiguous blocks of the fitting rows (boolean masks)."""
    idx = np.flatnonzero(fit)
    out = []
    for part in np.array_split(idx, k):
        m = np.zeros_like(fit)
        m[part] = True
        out.append(m)
    return out


#: in cross-validation, a column with less than this share of its energy (over the fitting rows)
#: in a fold's training rows is one those rows cannot estimate: it is left out of that fold
CV_MIN_TRAIN_SHARE = 1e-3


def _cv_rss(
    A: np.ndarray,
    y: np.ndarray,
    folds: list[np.ndarray],
    ridge: np.ndarray | None = None,
    n_fixed: int | None = None,
) -> float:
    """Residual sum of squares of each block predicted from the others.

    Without a ridge, a column after the first ``n_fixed`` (the nominal ones, always kept;
    None keeps every column) that is nearly silent in a fold's training rows (a stop reached
    almost only in the test block, a step in time just before its end) is left out of that
    fold: its coefficient, estimated from a handful of rows, would blow the prediction up by
    orders of magnitude; left out, the fold predicts what the nominal model does: no gain."""
    total = 0.0
    everything = np.logical_or.reduce(folds)
    energy = (A[everything] ** 2).sum(0)
    scale = None if ridge is None else np.sqrt(energy)
    for test in folds:
        train = everything & ~test
        cols = np.arange(A.shape[1])
        if ridge is None and n_fixed is not None:
            share = (A[train] ** 2).sum(0) / np.where(energy > 0, energy, 1.0)
            cols = cols[(cols < n_fixed) | (share >= CV_MIN_TRAIN_SHARE)]
        theta = lstsq(
            A[train][:, cols],
            y[train],
            None if ridge is None else ridge[cols],
            None if scale is None else scale[cols],
        )
        total += float(np.sum((y[test] - A[test][:, cols] @ theta) ** 2))
    return total


def fit_candidate(cand: Candidate, A0, B, y, fit, ho) -> dict | None:
    A = np.column_stack([A0, B])
    theta = lstsq(A[fit], y[fit])
    coef = theta[A0.shape[1] :]
    pos = cand.positive or (False,) * len(coef)
    if any(p and c <= 0 for p, c in zip(pos, coef)):
        return None
    r = y - A @ theta
    return {
        "rss_fit": float(np.sum(r[fit] ** 2)),
        "rss_ho": float(np.sum(r[ho] ** 2)) if ho.any() else None,
        "coef": dict(zip(cand.coef_names, map(float, coef))),
        "fixed": dict(cand.fixed),
        "theta": [float(v) for v in theta],
    }
