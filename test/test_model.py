"""The flat Pomdp container: validation messages and fingerprints."""
import numpy as np
import pytest
import scipy.sparse as sp

from pearl_pomdp.model.pomdp import Pomdp


def tiger_arrays():
    T = np.stack([np.eye(2), np.full((2, 2), 0.5), np.full((2, 2), 0.5)])
    O = np.stack([[[0.85, 0.15], [0.15, 0.85]], np.full((2, 2), 0.5), np.full((2, 2), 0.5)])
    R = np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]])
    return T, O, R


def test_create_and_shapes():
    T, O, R = tiger_arrays()
    m = Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                     ["tiger-left", "tiger-right"], T, O, R, discount=0.95)
    assert (m.num_states, m.num_actions, m.num_observations) == (2, 3, 2)
    assert np.allclose(m.b0, [0.5, 0.5])
    assert not m.is_sparse
    assert np.array_equal(m.T_dense(), T)


def test_row_error_names_action_and_state():
    T, O, R = tiger_arrays()
    T[1, 0] = [0.5, 0.4]
    with pytest.raises(ValueError, match=r"T\[open-left\]\[tiger-left, :\] sums to 0.9"):
        Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                     ["tiger-left", "tiger-right"], T, O, R)


def test_fingerprint_same_for_sparse_and_dense_and_changes_with_reward():
    T, O, R = tiger_arrays()
    names = (["l", "r"], ["listen", "ol", "or"], ["hl", "hr"])
    dense = Pomdp.create(*names, T, O, R, sparse=False)
    sparse = Pomdp.create(*names, T, O, R, sparse=True)
    assert sparse.is_sparse and sp.issparse(sparse.T[0])
    assert dense.fingerprint() == sparse.fingerprint()
    R2 = R.copy()
    R2[0, 0] = -2
    assert Pomdp.create(*names, T, O, R2).fingerprint() != dense.fingerprint()


def test_create_copies_the_callers_arrays():
    T, O, R = tiger_arrays()
    m = Pomdp.create(["l", "r"], ["listen", "ol", "or"], ["hl", "hr"], T, O, R)
    m.R[0, 0] = 99.0
    m.O[0, 0, 0] = 0.5
    m.T[0][0, 0] = 0.0
    assert R[0, 0] == -1.0 and O[0, 0, 0] == 0.85 and T[0][0, 0] == 1.0
