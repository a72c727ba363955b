"""pidyn's own implementations held to the reference implementations of the field, each test
skipped where its package is absent (``pip install 'pidyn[dev]'`` brings filterpy and
statsmodels; quakeio installs OpenSees and is not a dependency)."""

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import cont2discrete

from pidyn.baselines.realization import hold_integrals
from pidyn.baselines.ukf import _sigma_points, _weights
from pidyn.refine.uncertainty import sandwich

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "n, alpha, beta, kappa", [(4, 0.5, 2.0, 0.0), (7, 1e-3, 2.0, 1.0), (2, 1.0, 0.0, 3.0)]
)
def test_the_ukf_weights_and_sigma_points_are_filterpys(n, alpha, beta, kappa):
    kalman = pytest.importorskip("filterpy.kalman")
    ref = kalman.MerweScaledSigmaPoints(n, alpha=alpha, beta=beta, kappa=kappa)
    lam, wm, wc = _weights(n, alpha, beta, kappa)
    assert np.allclose(wm, ref.Wm, rtol=1e-13, atol=0) and np.allclose(wc, ref.Wc, rtol=1e-13, atol=0)
    rng = np.random.default_rng(n)
    m = rng.normal(size=n)
    L = rng.normal(size=(n, n))
    P = L @ L.T + n * np.eye(n)
    assert np.allclose(_sigma_points(m, P, lam).T, ref.sigma_points(m, P), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("lags", [0, 1, 7, 40])
def test_the_newey_west_long_run_covariance_is_statsmodels(lags):
    sandwich_covariance = pytest.importorskip("statsmodels.stats.sandwich_covariance")
    rng = np.random.default_rng(lags)
    e = rng.normal(size=(500, 3))
    g = np.cumsum(e, axis=0) * 0.1 + e  # correlated in time, as a model's smooth error is
    ours = sandwich(g, np.ones(len(g)), [slice(None)], lags)
    ref = sandwich_covariance.S_hac_simple(g, nlags=lags)
    assert np.allclose(ours, ref, rtol=1e-12, atol=0)
    # two channels sharing the samples: their scores add before the products
    ours2 = sandwich(np.vstack([g, 2 * g]), np.ones(2 * len(g)), [slice(0, 500), slice(500, 1000)], lags)
    assert np.allclose(ours2, 9 * ref, rtol=1e-12, atol=0)


@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_the_realizations_hold_integrals_are_scipys_first_order_hold(dt):
    Ac = np.array(
        [[0.0, 1.0, 0.0, 0.0], [-400.0, -0.8, 150.0, 0.0], [0.0, 0.0, 0.0, 1.0], [150.0, 0.0, -900.0, -1.2]]
    )
    n = Ac.shape[0]
    P1, P2 = hold_integrals(Ac, dt)
    Ad, Bd, _, Dd, _ = cont2discrete((Ac, np.eye(n), np.eye(n), np.zeros((n, n))), dt, method="foh")
    assert np.allclose(Ad, expm(Ac * dt), rtol=1e-12, atol=1e-14)
    assert np.allclose(Dd, P2, rtol=1e-10, atol=1e-15)  # D = D_c + C P2 B_c with C = B_c = I
    assert np.allclose(Bd, P1 - P2 + Ad @ P2, rtol=1e-10, atol=1e-15)


#: three archives of other eras and formats in `make test` (1986 film-era, 1992 main shock, a 2010s
#: digital one); every shipped archive in the second proofs
SOME_ARCHIVES = ("capemendocino_21nov1986", "petrolia_25apr1992", "nc73351710")


@pytest.mark.parametrize(
    "which",
    [pytest.param(SOME_ARCHIVES, id="some"), pytest.param(None, id="all", marks=pytest.mark.second_proof)],
)
def test_the_csmip_reader_reads_what_quakeio_reads(which):
    quakeio = pytest.importorskip("quakeio")
    from pidyn.data.csmip import read_archive

    compared = 0
    archives = sorted((ROOT / "data" / "painter_street" / "records").glob("*.zip"))
    if which is not None:
        archives = [p for p in archives if p.name.startswith(which)]
        assert len(archives) == len(which)
    for path in archives:
        try:
            event = quakeio.read(str(path), exclusions=["filter*"])
        except Exception:  # an archive quakeio cannot read (film-era channels of unequal lengths)
            continue
        for number, ch in read_archive(path).channels.items():
            theirs = event.match("l", station_channel=f"{number}")
            if theirs is None:
                continue
            ref = np.asarray(theirs.accel.data, float)
            assert len(ref) == ch.n, (path.name, number)
            scale = np.max(np.abs(ch.acc)) / np.max(np.abs(ref))  # quakeio keeps the files' cm/s^2
            assert scale == pytest.approx(0.01, rel=1e-9) or scale == pytest.approx(1.0, rel=1e-9)
            assert np.allclose(ch.acc, scale * ref, rtol=1e-9, atol=1e-12), (path.name, number)
            compared += 1
    assert compared > 0
