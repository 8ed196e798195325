"""The projection operator Phi: adjoint, brute-force forward, patch matrices, phases."""

from __future__ import annotations

import numpy as np
import pytest

from lfproc.errors import InputError, ShapeError
from lfproc.camera.projection import (
    CFA_PATTERNS,
    MASK_KINDS,
    MaskCode,
    ProjectionOperator,
    build_operator,
    cfa_index_map,
    make_mask,
    sampling_rate,
)

VIEWS = (5, 5)
SIZE = (16, 18)


def _operator(kind, period, shots, cfa="RGGB", size=SIZE, seed=1):
    mask = make_mask(kind, shots=shots, views=VIEWS, size=size, period=period, random_state=seed)
    return mask, build_operator(mask, views=VIEWS, size=size, cfa_pattern=cfa, dtype=np.float64)


@pytest.mark.parametrize("kind", MASK_KINDS)
@pytest.mark.parametrize("period", [None, 4, 3])
@pytest.mark.parametrize("shots", [1, 2, 3])
def test_adjoint_identity(kind, period, shots):
    rng = np.random.default_rng(10)
    for cfa in CFA_PATTERNS:
        _, op = _operator(kind, period, shots, cfa)
        x = rng.standard_normal(op.in_shape)
        y = rng.standard_normal(op.out_shape)
        lhs = np.vdot(op.forward(x), y)
        rhs = np.vdot(x, op.adjoint(y))
        assert lhs == pytest.approx(rhs, rel=1e-12, abs=1e-12)
        # float32 inputs keep float32 and still agree to float precision
        lhs32 = np.vdot(op.forward(x.astype(np.float32)).astype(np.float64), y)
        assert lhs32 == pytest.approx(lhs, rel=1e-4)


@pytest.mark.parametrize("kind", MASK_KINDS)
@pytest.mark.parametrize("period", [None, 3])
def test_forward_matches_the_model_sum(kind, period):
    """y_s(p) = sum_{v,u} M_s(v,u,p,c(p)) L(v,u,p,c(p)), evaluated pixel by pixel."""
    mask, op = _operator(kind, period, 2, "GBRG", size=(6, 7))
    lf = np.random.default_rng(2).random(op.in_shape)
    full = mask.expand(views=VIEWS, size=(6, 7))
    cfa = cfa_index_map("GBRG", (6, 7))
    want = np.zeros(op.out_shape)
    for s in range(2):
        for y in range(6):
            for x in range(7):
                c = cfa[y, x]
                want[s, y, x] = (full[s, :, :, y, x, c] * lf[:, :, y, x, c]).sum()
    np.testing.assert_allclose(op.forward(lf), want, rtol=1e-12)


def test_cfa_map_is_row_major_from_top_left():
    np.testing.assert_array_equal(cfa_index_map("RGGB", (2, 2)), [[0, 1], [1, 2]])
    np.testing.assert_array_equal(cfa_index_map("GBRG", (2, 3)), [[1, 2, 1], [0, 1, 0]])
    np.testing.assert_array_equal(cfa_index_map("RGGB", (2, 2), offset=(1, 1)), [[2, 1], [1, 0]])
    with pytest.raises(InputError, match="cfa_pattern: expected one of RGGB"):
        cfa_index_map("RGBG", (2, 2))


def test_shifted_mask_is_one_mask_seen_with_a_view_dependent_shift():
    mask = make_mask("shifted", shots=1, views=VIEWS, size=(8, 8), shift=1, random_state=0)
    full = mask.expand(views=VIEWS, size=(8, 8))
    # view (v, u+1) at column x sees what view (v, u) sees at column x+1
    np.testing.assert_array_equal(full[0, 2, 3, :, :-1], full[0, 2, 2, :, 1:])
    np.testing.assert_array_equal(full[0, 3, 1, :-1], full[0, 2, 1, 1:])
    assert mask.codes.shape == (1, 12, 12, 3)


@pytest.mark.parametrize("kind", MASK_KINDS)
@pytest.mark.parametrize("period", [None, 4])
@pytest.mark.parametrize("shots", [1, 2])
def test_patch_matrix_is_the_operator_restricted_to_the_patch(kind, period, shots):
    _, op = _operator(kind, period, shots, "GRBG")
    rng = np.random.default_rng(3)
    for top, left, size in [(0, 0, 9), (3, 5, 9), (7, 9, 9), (5, 2, 4)]:
        lf = np.zeros(op.in_shape)
        patch = rng.random((*VIEWS, size, size, 3))
        lf[:, :, top:top + size, left:left + size] = patch  # supported on the patch only
        y = op.forward(lf)
        P = op.patch_matrix(top, left, size)
        assert P.shape == (shots * size * size, VIEWS[0] * VIEWS[1] * size * size * 3)
        np.testing.assert_allclose(P @ patch.reshape(-1), y[:, top:top + size, left:left + size].reshape(-1),
                                   rtol=1e-12, atol=1e-12)
        outside = np.ones(op.out_shape, bool)
        outside[:, top:top + size, left:left + size] = False
        assert not y[outside].any()
        assert (np.count_nonzero(P, axis=1) <= VIEWS[0] * VIEWS[1]).all()
        # restrict gives an operator of the window that agrees
        sub = op.restrict(top, left, size)
        np.testing.assert_allclose(sub.forward(patch), y[:, top:top + size, left:left + size], rtol=1e-12)
        np.testing.assert_allclose(sub.patch_matrix(0, 0, size), P)


def test_patch_sparse_batch_matches_dense_patch_matrices():
    _, op = _operator("random", None, 2, "BGGR")
    tops, lefts = np.array([0, 4, 7, 2]), np.array([0, 8, 9, 3])
    cols, vals = op.patch_sparse(tops, lefts, 9)
    assert cols.shape == vals.shape == (4, 2 * 81, 25)
    x = np.random.default_rng(4).random((25 * 81 * 3, 7))
    for b, (t, l) in enumerate(zip(tops, lefts)):
        P = op.patch_matrix(int(t), int(l), 9)
        np.testing.assert_allclose((vals[b][..., None] * x[cols[b]]).sum(1), P @ x, rtol=1e-12)


def test_phases_of_periodic_masks():
    _, op = _operator("random", 4, 1, size=(24, 24))
    assert op.period == (4, 4)
    assert op.shares_operator(4) and op.n_phases(8) == 1
    np.testing.assert_array_equal(op.patch_matrix(0, 0), op.patch_matrix(4, 12))
    assert op.phase(4, 12) == op.phase(0, 0) == (0, 0)
    # period 3 combined with the Bayer period 2: 6; stride 4 -> (6 / gcd(6, 4))^2 = 9 phases
    _, op3 = _operator("shifted", 3, 2, size=(30, 30))
    assert op3.period == (6, 6) and op3.n_phases(4) == 9 and not op3.shares_operator(4)
    assert op3.shares_operator(6)
    np.testing.assert_array_equal(op3.patch_matrix(2, 4), op3.patch_matrix(14, 16))
    assert not np.array_equal(op3.patch_matrix(0, 0), op3.patch_matrix(0, 4))
    # a restricted operator keeps its phase on the full sensor
    assert op3.restrict(2, 4, 9).phase(0, 0) == op3.phase(2, 4)
    _, free = _operator("random", None, 1)
    assert free.period is None and free.n_phases(4) is None and not free.shares_operator(4)
    assert free.phase(3, 3) is None


def test_linear_operator_and_sampling_rate():
    _, op = _operator("random", None, 2)
    lin = op.as_linear_operator()
    assert lin.shape == (2 * 16 * 18, 25 * 16 * 18 * 3)
    rng = np.random.default_rng(5)
    x = rng.standard_normal(lin.shape[1])
    y = rng.standard_normal(lin.shape[0])
    np.testing.assert_allclose(lin.matvec(x), op.forward(x.reshape(op.in_shape)).ravel())
    np.testing.assert_allclose(lin.rmatvec(y), op.adjoint(y.reshape(op.out_shape)).ravel())
    np.testing.assert_allclose(lin.matmat(np.stack([x, 2 * x], 1))[:, 1], 2 * lin.matvec(x))
    assert f"{100 * sampling_rate(shots=1, views=(5, 5)):.2f} %" == "1.33 %"
    assert f"{100 * op.sampling_rate:.2f} %" == "2.67 %"
    # the diagonal of Phi^T Phi
    e = np.zeros(op.in_shape)
    e[1, 2, 3, 4, int(op.cfa_index[3, 4])] = 1
    assert np.vdot(op.forward(e), op.forward(e)) == pytest.approx(op.normal_diagonal()[1, 2, 3, 4].sum())


def test_bad_input_is_refused():
    mask, op = _operator("random", None, 1)
    with pytest.raises(ShapeError, match=r"forward: expected a light field of shape \(5, 5, 16, 18, 3\)"):
        op.forward(np.zeros((5, 5, 16, 18, 1)))
    with pytest.raises(ShapeError, match="adjoint: expected sensor images"):
        op.adjoint(np.zeros((2, 16, 18)))
    with pytest.raises(InputError, match="does not fit in the sensor"):
        op.patch_matrix(10, 0, 9)
    with pytest.raises(InputError, match="mask: expected one of random, shifted"):
        make_mask("checker", shots=1, views=VIEWS, size=SIZE)
    with pytest.raises(InputError, match="shots: expected an integer >= 1"):
        make_mask("random", shots=0, views=VIEWS, size=SIZE)
    with pytest.raises(InputError, match=r"transmittances in \[0, 1\]"):
        MaskCode("random", np.full((1, 5, 5, 4, 4, 3), 1.5), period=4)
    with pytest.raises(ShapeError, match="random mask: codes cover"):
        build_operator(mask, views=VIEWS, size=(8, 8))
    small = make_mask("shifted", shots=1, views=VIEWS, size=(8, 8), random_state=0)
    with pytest.raises(ShapeError, match="too small"):
        build_operator(small, views=VIEWS, size=(16, 16))
    with pytest.raises(ShapeError, match="cfa_index"):
        ProjectionOperator(np.ones((1, 5, 5, 4, 4)), np.zeros((3, 3), int))
