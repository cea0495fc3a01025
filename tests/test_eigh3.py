"""materials.piola.eigh3, the allocation-free 3x3 symmetric eigen-decomposition of the
Mohr-Coulomb return and Hencky's log strain, against LAPACK (np.linalg.eigh)."""
import numpy as np
import pytest

from fenicsmpm.materials.piola import eigh3


def _cases():
    rng = np.random.default_rng(7)
    X = rng.standard_normal((400, 3, 3)) * 1e5
    S = X + X.transpose(0, 2, 1)
    S[:100, 0, 2] = S[:100, 2, 0] = S[:100, 1, 2] = S[:100, 2, 1] = 0.0     # plane strain
    S[100] = -1e4 * np.eye(3)                                                # triple
    S[101] = 0.0                                                             # stress-free
    S[102] = np.diag([3.0, 1.0, 2.0])                                        # unordered diagonal
    S[103] = np.diag([2.0, 2.0, -1.0]) + 1e-9 * (X[103] + X[103].T) / 1e5   # nearly double
    S[104, 0, 0] = S[104, 1, 1]                                              # double in plane
    S[104, 0, 2:] = S[104, 2:, 0] = S[104, 1, 2:] = S[104, 2:, 1] = 0.0
    return S


@pytest.mark.parametrize("k", range(0, 400, 7))
def test_eigh3_matches_lapack(k):
    S = _cases()[k]
    w, V = np.empty(3), np.empty((3, 3))
    eigh3(S, w, V)
    scale = max(np.abs(S).max(), 1e-300)
    wl = np.linalg.eigh(S)[0]
    assert np.all(np.diff(w) >= 0.0)                                # ascending
    assert np.abs(w - wl).max() <= 1e-14 * scale                    # LAPACK's eigenvalues
    assert np.abs(V.T @ V - np.eye(3)).max() <= 1e-14               # orthonormal
    assert np.abs(V @ np.diag(w) @ V.T - S).max() <= 1e-14 * scale  # S = V diag(w) V^T


def test_eigh3_special_cases():
    S = _cases()
    for k in range(100, 105):
        w, V = np.empty(3), np.empty((3, 3))
        eigh3(S[k], w, V)
        scale = max(np.abs(S[k]).max(), 1e-300)
        assert np.abs(w - np.linalg.eigh(S[k])[0]).max() <= 1e-14 * scale
        assert np.abs(V @ np.diag(w) @ V.T - S[k]).max() <= 1e-14 * scale
