"""Dictionaries: Batch-OMP against scikit-learn's OMP, K-SVD on a planted dictionary, files, training, CLI."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.dictionary import (
    Dictionary, batch_omp, dct_dictionary, evaluate_dictionary, ksvd, load_dictionary, save_dictionary,
    train_dictionary, training_patches,
)
from lfproc.dictionary._patches import extract_patches
from lfproc.dictionary._files import HEADER_NAME
from lfproc.errors import FileFormatError, InputError, LfprocError, ShapeError
from lfproc.synth import synthesize


def _random_dictionary(n, k, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, k))
    return (d / np.linalg.norm(d, axis=0)).astype(np.float32)


def _sparse_signals(d, n_signals, t, seed=1):
    rng = np.random.default_rng(seed)
    k = d.shape[1]
    a = np.zeros((k, n_signals))
    for i in range(n_signals):
        a[rng.choice(k, t, replace=False), i] = rng.choice([-1, 1], t) * rng.uniform(0.5, 2.0, t)
    return a, d.astype(np.float64) @ a


# -- Batch-OMP ---------------------------------------------------------------------------------

def test_batch_omp_recovers_planted_supports_exactly():
    d = _random_dictionary(256, 512)
    a, x = _sparse_signals(d, 400, 8)
    coef = batch_omp(d, x, 8)
    assert coef.shape == (512, 400)
    np.testing.assert_array_equal(coef != 0, a != 0)
    np.testing.assert_allclose(coef, a, atol=2e-4)


@pytest.mark.parametrize("n_signals, n_tol", [(200, 50),  # fast: the same check on fewer signals
                                               pytest.param(3000, 500, marks=pytest.mark.slow)])
def test_batch_omp_agrees_with_scikit_learn(n_signals, n_tol):
    """Reference: sklearn.linear_model.orthogonal_mp_gram (float64, one signal at a time)."""
    from sklearn.linear_model import orthogonal_mp_gram

    d = _random_dictionary(128, 300, seed=3)
    x = np.random.default_rng(4).standard_normal((128, n_signals)).astype(np.float32)
    ours = batch_omp(d, x, 10)
    d64 = d.astype(np.float64)
    ref = orthogonal_mp_gram(d64.T @ d64, d64.T @ x.astype(np.float64), n_nonzero_coefs=10)
    same_support = ((ours != 0) == (ref != 0)).all(axis=0)
    assert same_support.mean() >= 0.999
    np.testing.assert_allclose(ours[:, same_support], ref[:, same_support], atol=5e-4)
    # error-constrained stop (scikit-learn's tol overrides the sparsity: give ours room to reach it)
    tol = 0.5 * float(np.median((x.astype(np.float64) ** 2).sum(axis=0)))
    ours_t = batch_omp(d, x[:, :n_tol], 128, tol=tol)
    ref_t = orthogonal_mp_gram(d64.T @ d64, d64.T @ x[:, :n_tol].astype(np.float64), tol=tol,
                               norms_squared=(x[:, :n_tol].astype(np.float64) ** 2).sum(axis=0))
    assert ((ours_t != 0) == (ref_t != 0)).all(axis=0).mean() >= 0.99
    used = (ours_t != 0).sum(axis=0)
    assert 5 < used.mean() < 128  # the tolerance, not the sparsity, stopped the signals


def test_batch_omp_single_signal_chunks_and_zero_signal():
    d = _random_dictionary(64, 128, seed=5)
    a, x = _sparse_signals(d, 50, 4, seed=6)
    full = batch_omp(d, x, 4)
    # other chunkings give the same supports (float32 GEMMs of other shapes may round differently)
    for other in (batch_omp(d, x, 4, chunk_size=7), batch_omp(d, x[:, 3], 4)[:, None]):
        np.testing.assert_array_equal(other != 0, full[:, :other.shape[1]] != 0 if other.shape[1] > 1
                                      else full[:, 3:4] != 0)
    np.testing.assert_allclose(batch_omp(d, x, 4, chunk_size=7), full, atol=1e-5)
    zero = batch_omp(d, np.zeros((64, 2)), 4)
    assert not zero.any()


def _coherent_dictionary(n, pairs, coherence, seed=0):
    """Pairs of unit atoms at the given coherence (the shipped dictionary has atoms at 0.99)."""
    rng = np.random.default_rng(seed)
    base = rng.standard_normal((n, pairs))
    base /= np.linalg.norm(base, axis=0)
    other = rng.standard_normal((n, pairs))
    other -= base * (base * other).sum(axis=0)
    other /= np.linalg.norm(other, axis=0)
    twin = coherence * base + np.sqrt(1 - coherence**2) * other
    return np.concatenate([base, twin], axis=1).astype(np.float32)


@pytest.mark.parametrize("coherence", [0.99, 1 - 1e-6])
def test_batch_omp_on_a_coherent_dictionary_neither_fails_nor_gives_nan(coherence):
    """Pairs of atoms at coherence 0.99 (and near-duplicates at 1 - 1e-6, below float32's resolution of the
    Gram matrix): finite codes, a residual no larger than the signal, and the same supports as scikit-learn
    (float64) for almost every signal at 0.99."""
    from sklearn.linear_model import orthogonal_mp_gram

    d = _coherent_dictionary(64, 96, coherence)
    rng = np.random.default_rng(8)
    a = np.zeros((192, 2000))
    for i in range(2000):  # signals using both atoms of a pair
        p = rng.choice(96, 3, replace=False)
        a[np.r_[p, p + 96], i] = rng.standard_normal(6)
    x = (d.astype(np.float64) @ a + 0.01 * rng.standard_normal((64, 2000))).astype(np.float32)
    coef = batch_omp(d, x, 10)
    assert np.isfinite(coef).all()
    resid = x.astype(np.float64) - d.astype(np.float64) @ coef
    assert ((resid**2).sum(axis=0) <= 1.0001 * (x.astype(np.float64) ** 2).sum(axis=0)).all()
    if coherence == 0.99:
        d64 = d.astype(np.float64)
        ref = orthogonal_mp_gram(d64.T @ d64, d64.T @ x.astype(np.float64), n_nonzero_coefs=10)
        assert ((coef != 0) == (ref != 0)).all(axis=0).mean() >= 0.99
        ref_err = ((x.astype(np.float64) - d64 @ ref) ** 2).sum(axis=0)
        np.testing.assert_allclose((resid**2).sum(axis=0).mean(), ref_err.mean(), rtol=1e-3)
    else:  # a near-duplicate is dependent: never both atoms of a pair, and no coefficient blow-up
        assert not ((coef[:96] != 0) & (coef[96:] != 0)).any()
        assert np.abs(coef).max() < 100


@pytest.mark.parametrize("args, match", [
    (("bad-d",), "2-D array"),
    (("nan-d",), "NaN"),
    (("unnormed",), "unit-norm"),
    (("wrong-n",), "expected shape"),
    (("t0",), "n_nonzero_coefs"),
    (("t-big",), "n_nonzero_coefs"),
    (("nan-x",), "finite"),
])
def test_batch_omp_bad_input(args, match):
    d = _random_dictionary(16, 32)
    x = np.ones((16, 3))
    t = 3
    case = args[0]
    if case == "bad-d":
        d = d[0]
    elif case == "nan-d":
        d = d.copy()
        d[0, 0] = np.nan
    elif case == "unnormed":
        d = d * 2
    elif case == "wrong-n":
        x = np.ones((15, 3))
    elif case == "t0":
        t = 0
    elif case == "t-big":
        t = 17
    elif case == "nan-x":
        x[0, 0] = np.nan
    with pytest.raises(InputError, match=match):
        batch_omp(d, x, t)


# -- K-SVD -------------------------------------------------------------------------------------

def _planted(seed=1):
    """The synthetic test of Aharon, Elad and Bruckstein (2006): n = 20, K = 50, 1500 signals of
    sparsity 3, white noise at 20 dB SNR."""
    rng = np.random.default_rng(seed)
    d_true = _random_dictionary(20, 50, seed=seed + 10).astype(np.float64)
    a = np.zeros((50, 1500))
    for i in range(1500):
        a[rng.choice(50, 3, replace=False), i] = rng.standard_normal(3)
    x = d_true @ a
    noise = rng.standard_normal(x.shape)
    noise *= np.linalg.norm(x) / np.linalg.norm(noise) / 10.0  # 20 dB
    return d_true, (x + noise).T.astype(np.float32)


def test_ksvd_recovers_planted_dictionary():
    d_true, x = _planted()
    result = ksvd(x, 50, 3, 60, random_state=0)
    found = (np.abs(result.atoms.T.astype(np.float64) @ d_true).max(axis=0) > 0.99).mean()
    assert found >= 0.90, f"only {found:.0%} of the planted atoms found"
    assert result.errors[-1] < result.errors[0]
    assert result.final_error < 0.02  # noise floor: 1 % of the energy at 20 dB SNR
    np.testing.assert_allclose(np.linalg.norm(result.atoms, axis=0), 1, atol=1e-5)


def test_ksvd_resumes_from_checkpoint_with_the_same_result(tmp_path):
    _, x = _planted(seed=2)

    class Stop(Exception):
        pass

    def stop_after_2(iteration, _error):
        if iteration == 2:
            raise Stop

    with pytest.raises(Stop):
        ksvd(x, 50, 3, 5, random_state=7, checkpoint=tmp_path / "ck", callback=stop_after_2)
    resumed = ksvd(x, 50, 3, 5, random_state=7, checkpoint=tmp_path / "ck")
    straight = ksvd(x, 50, 3, 5, random_state=7)
    assert resumed.resumed_from == 2
    np.testing.assert_array_equal(resumed.atoms, straight.atoms)
    assert resumed.errors == straight.errors
    # a checkpoint of other parameters is refused, not silently used
    with pytest.raises(InputError, match="another training run"):
        ksvd(x, 40, 3, 5, random_state=7, checkpoint=tmp_path / "ck")


@pytest.mark.slow  # a Dask cluster
def test_ksvd_on_a_dask_cluster_gives_the_in_process_result():
    distributed = pytest.importorskip("distributed")
    _, x = _planted(seed=3)
    local = ksvd(x, 50, 3, 2, random_state=1, chunk_size=400)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                                   silence_logs=40) as cluster:
        remote = ksvd(x, 50, 3, 2, random_state=1, chunk_size=400, scheduler=cluster.scheduler_address)
    np.testing.assert_array_equal(remote.atoms, local.atoms)


@pytest.mark.parametrize("from_file", [False, True])
def test_ksvd_atom_update_without_the_residual_matches_the_residual_formula(monkeypatch, tmp_path, from_file):
    """The approximate K-SVD update written on X and the codes (d = X_I^T g - D_S Gamma_S g, g = X_I d - Gamma_S^T D_S^T d)
    is the update on the residual (float64 reference: E_j = E_I + g d_j^T, d = E_j^T g / ||.||, g = E_j d,
    E_I = E_j - g d^T, atoms in the same order); the users' rows read in chunks (popular atoms), from memory or a
    file, with a peak of extra memory far below the signals' size."""
    import tracemalloc

    from lfproc.dictionary import _ksvd

    monkeypatch.setattr(_ksvd, "_UPDATE_CHUNK_BYTES", 2**20, raising=False)
    rng = np.random.default_rng(9)
    n_sig, n, k, t = 40000, 128, 6, 3
    atoms_t = _random_dictionary(n, k, seed=9).T.copy()
    idx = np.stack([rng.permutation(5)[:t] for _ in range(n_sig)]).astype(np.int32)  # atoms 0..4, 5 unused
    idx[::7, 2] = -1  # some signals use fewer atoms
    val = rng.standard_normal((n_sig, t)).astype(np.float32)
    val[idx < 0] = 0
    x = (_ksvd._codes_matrix(idx, val, k) @ atoms_t + 0.1 * rng.standard_normal((n_sig, n))).astype(np.float32)
    ref_atoms, ref_val = atoms_t.astype(np.float64), val.astype(np.float64)
    codes = np.zeros((n_sig, k))
    np.add.at(codes, (np.arange(n_sig)[:, None].repeat(t, 1)[idx >= 0], idx[idx >= 0]), ref_val[idx >= 0])
    ref_resid = x - codes @ ref_atoms
    for j in np.random.default_rng(1).permutation(k):
        users = np.flatnonzero(codes[:, j])
        if not len(users):
            continue
        g = codes[users, j]
        e = ref_resid[users] + np.outer(g, ref_atoms[j])
        d = e.T @ g
        d /= np.linalg.norm(d)
        g = e @ d
        ref_resid[users] = e - np.outer(g, d)
        ref_atoms[j], codes[users, j] = d, g
    if from_file:
        np.save(tmp_path / "x.npy", x)
        signals = _ksvd.TrainingSignals(tmp_path / "x.npy")
    else:
        signals = _ksvd.TrainingSignals(x)
    tracemalloc.start()
    unused = _ksvd._update_atoms(atoms_t, idx, val, signals, np.random.default_rng(1), t)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert unused == [5]
    assert peak < 0.3 * x.nbytes, (peak, x.nbytes)  # per-user bookkeeping (N T entries), no N x n array
    np.testing.assert_allclose(atoms_t[:5], ref_atoms[:5], atol=1e-5)
    used = idx >= 0
    np.testing.assert_allclose(val[used], codes[np.nonzero(used)[0], idx[used]], atol=1e-4)


def test_ksvd_from_a_file_keeps_no_copy_of_the_signals(tmp_path):
    """One K-SVD iteration on signals in a .npy file: peak allocations far below the signals' size (before: the
    N x n residual, as large as the signals, was kept through the iteration), and the result of training on the
    same signals in memory."""
    import tracemalloc

    rng = np.random.default_rng(4)
    x = rng.standard_normal((10000, 512)).astype(np.float32)
    np.save(tmp_path / "x.npy", x)
    in_memory = ksvd(x, 16, 2, 1, random_state=0, chunk_size=500)
    tracemalloc.start()
    from_file = ksvd(tmp_path / "x.npy", 16, 2, 1, random_state=0, chunk_size=500)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 0.3 * x.nbytes, (peak, x.nbytes)
    np.testing.assert_array_equal(from_file.atoms, in_memory.atoms)
    assert from_file.errors == in_memory.errors and from_file.final_error == in_memory.final_error


def test_ksvd_replaces_atoms_by_the_worst_represented_signals_without_duplicates():
    """Known answer: signals 7 and 3 have the largest residuals, signal 5 (third) is a copy of signal 7 and
    signal 11 (fourth) is within 0.99 of a staying atom: two unused atoms become signals 7 and 3; a third one
    skips 5 and 11 and takes the fifth worst, 2."""
    from lfproc.dictionary._ksvd import TrainingSignals, _clear_atoms

    rng = np.random.default_rng(10)
    n, k, n_sig = 32, 6, 20
    x = rng.standard_normal((n_sig, n)).astype(np.float32)
    atoms_t = _random_dictionary(n, k, seed=11).T.copy()
    x[5] = 2 * x[7]
    x[11] = 3 * atoms_t[0]
    err = np.full(n_sig, 0.01)
    for rank, s in enumerate([7, 3, 5, 11, 2]):
        err[s] = 1.0 - 0.1 * rank
    idx = np.zeros((n_sig, 1), np.int32)  # atoms 0, 1 and 5 used, 2..4 unused
    idx[:8] = 1
    idx[8:12] = 5
    done = _clear_atoms(atoms_t, TrainingSignals(x), err, idx, [2, 3, 4], min_usage=1, max_coherence=0.99)
    assert done == [2, 3, 4]
    for j, s in zip(done, [7, 3, 2]):
        np.testing.assert_allclose(atoms_t[j], x[s] / np.linalg.norm(x[s]), rtol=1e-5, atol=1e-6)


def test_ksvd_bad_input():
    x = np.ones((10, 4), dtype=np.float32)
    with pytest.raises(InputError, match="n_atoms"):
        ksvd(x, 11, 2, 1)
    with pytest.raises(InputError, match="n_nonzero_coefs"):
        ksvd(x, 5, 6, 1)
    with pytest.raises(InputError, match="integer seed"):
        ksvd(x, 5, 2, 1, checkpoint="ck")


# -- files ---------------------------------------------------------------------------------------

def _small_dictionary(**kw):
    d = dct_dictionary((3, 3, 2, 2, 3), 150)
    return Dictionary(atoms=d.atoms, patch=d.patch, sparsity=4, preset="tiny", provenance={"seed": 1},
                      usage=np.arange(150), **kw)


def test_dictionary_file_round_trip_and_reproducible_bytes(tmp_path):
    d = _small_dictionary()
    p32 = save_dictionary(d, tmp_path / "a.npz", dtype="float32")
    back = load_dictionary(p32)
    np.testing.assert_array_equal(back.atoms, d.atoms)
    assert back.patch == d.patch and back.sparsity == 4 and back.preset == "tiny" and back.provenance == {"seed": 1}
    np.testing.assert_array_equal(back.usage, np.arange(150))
    p16 = save_dictionary(d, tmp_path / "b.npz")
    back16 = load_dictionary(p16)
    np.testing.assert_allclose(back16.atoms, d.atoms, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(back16.atoms, axis=0), 1, atol=1e-6)
    save_dictionary(d, tmp_path / "c.npz")
    assert hashlib.sha256(p16.read_bytes()).digest() == hashlib.sha256((tmp_path / "c.npz").read_bytes()).digest()
    with pytest.raises(LfprocError, match="exists"):
        save_dictionary(d, p16)
    with pytest.raises(ValueError):
        back.atoms[0, 0] = 1.0  # validated atoms are read-only


def _rewrite(src, dst, *, header=None, atoms=None):
    with zipfile.ZipFile(src) as zf:
        head = json.loads(zf.read(HEADER_NAME))
        members = {n: zf.read(n) for n in zf.namelist() if n != HEADER_NAME}
    if header:
        head.update(header)
    if atoms is not None:
        import io

        buf = io.BytesIO()
        np.lib.format.write_array(buf, atoms)
        members["atoms.npy"] = buf.getvalue()
    with zipfile.ZipFile(dst, "w") as zf:
        zf.writestr(HEADER_NAME, json.dumps(head))
        for n, b in members.items():
            zf.writestr(n, b)
    return dst


@pytest.mark.parametrize("case, match", [
    ("version", "schema_version"),
    ("shape", "expected shape"),
    ("nan", "NaN"),
    ("patch", "field 'n'"),
    ("huge", "field 'atoms'"),
    ("norm", "unit-norm"),
    ("truncated", "not an lfproc dictionary|corrupt"),
    ("nested", "nest|deep|depth"),
])
def test_dictionary_file_errors(tmp_path, case, match):
    src = save_dictionary(_small_dictionary(), tmp_path / "ok.npz", dtype="float32")
    dst = tmp_path / "bad.npz"
    atoms = np.array(load_dictionary(src).atoms)
    if case == "version":
        _rewrite(src, dst, header={"schema_version": 99})
    elif case == "shape":
        _rewrite(src, dst, atoms=atoms[:, :100])
    elif case == "nan":
        atoms[3, 5] = np.nan
        _rewrite(src, dst, atoms=atoms)
    elif case == "patch":
        _rewrite(src, dst, header={"patch": [5, 5, 2, 2, 3]})
    elif case == "huge":
        _rewrite(src, dst, header={"atoms": 10**9})
    elif case == "norm":
        _rewrite(src, dst, atoms=atoms * 1.5)
    elif case == "nested":  # JSON nested deeper than the reader accepts (not parsed: refused first)
        with zipfile.ZipFile(dst, "w") as zf:
            zf.writestr(HEADER_NAME, '{"schema": "lfproc.dictionary", "x": ' + "[" * 5000 + "]" * 5000 + "}")
    else:
        dst.write_bytes(src.read_bytes()[:300])
    with pytest.raises(FileFormatError, match=match) as info:
        load_dictionary(dst)
    assert str(dst) in str(info.value)


# -- patches, DCT, evaluation --------------------------------------------------------------------

def test_training_patches_are_seeded_normalised_and_reject_flat():
    lf = synthesize("checker", size=(40, 40), views=5, random_state=3)
    a, info = training_patches([lf], patch=(5, 5, 4, 4, 3), n_patches=300, random_state=1)
    b, _ = training_patches([lf], patch=(5, 5, 4, 4, 3), n_patches=300, random_state=1)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, rtol=1e-5)
    # a patch equals the light field's samples in (V, U, P, P, C) order
    raw = extract_patches(lf, (5, 5, 4, 4, 3), [7], [11])
    np.testing.assert_array_equal(raw[0], lf.data[:, :, 7:11, 11:15, :].reshape(-1))
    flat = np.full((5, 5, 30, 30, 3), 2.0, dtype=np.float32)
    flat[..., :15, :, :] = 1.0  # two flat halves: most patches are flat
    _, finfo = training_patches([flat], patch=(5, 5, 4, 4, 3), n_patches=200, random_state=0)
    assert finfo["rejected_flat"] > finfo["kept_flat"] > 0
    with pytest.raises(InputError, match="usable patches"):
        training_patches([np.zeros((5, 5, 10, 10, 3))], patch=(5, 5, 4, 4, 3), n_patches=10, random_state=0)
    with pytest.raises(ShapeError, match="views"):
        training_patches([synthesize("layers", size=(32, 32), views=3)], patch=(5, 5, 4, 4, 3), n_patches=10)
    with pytest.raises(ShapeError, match="smaller than"):
        training_patches([np.ones((5, 5, 3, 8, 3))], patch=(5, 5, 4, 4, 3), n_patches=10)


def _reference_dct_atoms(patch):
    """Independent reference: the orthonormal DCT-II atoms built by hand, ``(n, n)`` (columns), with each
    one's frequencies. Every axis of (V, U, P, P) uses scipy.fft.dct's type-II orthonormal matrix
    (its rows are the basis functions); the colour axis the luminance/opponent basis written out here
    ((1, 1, 1)/sqrt 3, (1, 0, -1)/sqrt 2, (1, -2, 1)/sqrt 6)."""
    from scipy.fft import dct

    colour = np.array([[1, 1, 1], [1, 0, -1], [1, -2, 1]]) / np.sqrt([[3], [2], [6]])
    mats = [dct(np.eye(s), norm="ortho", axis=0) for s in patch[:4]] + [colour if patch[4] == 3 else np.eye(1)]
    atoms, freqs = [], []
    for f in np.ndindex(*patch):
        atom = mats[0][f[0]]
        for m, k in zip(mats[1:], f[1:]):
            atom = np.multiply.outer(atom, m[k])
        atoms.append(atom.ravel())
        freqs.append(f)
    return np.array(atoms).T, np.array(freqs)


@pytest.mark.parametrize("patch", [(1, 1, 4, 4, 1), (2, 3, 4, 4, 3)])
def test_dct_dictionary_is_the_orthonormal_dct_ii(patch):
    """Reference: the hand-built separable DCT-II (scipy.fft.dct matrices, _reference_dct_atoms). The
    complete dictionary is that basis exactly: D^T R is a permutation matrix (each atom equals one
    reference atom, sign included), and its atoms come in order of total normalised frequency."""
    d = dct_dictionary(patch)
    ref, freqs = _reference_dct_atoms(patch)
    n = ref.shape[1]
    assert d.n_atoms == n
    match = d.atoms.T.astype(np.float64) @ ref
    np.testing.assert_allclose(np.sort(np.abs(match), axis=1)[:, -1], 1, atol=1e-6)
    perm = np.argmax(match, axis=1)
    assert sorted(perm) == list(range(n))  # one to one
    np.testing.assert_allclose(d.atoms, ref[:, perm], atol=1e-6)  # same atoms, same signs
    total = (freqs[perm, :4] / np.array(patch[:4])).sum(axis=1)
    assert np.all(np.diff(total) >= -1e-12)
    # a truncated dictionary keeps the lowest frequencies: on a 4 x 4 patch, 6 atoms are DC, the two
    # first harmonics and the three of total frequency 2/4
    six = dct_dictionary((1, 1, 4, 4, 1), 6)
    m6 = np.abs(six.atoms.T.astype(np.float64) @ _reference_dct_atoms((1, 1, 4, 4, 1))[0])
    got = {tuple(_reference_dct_atoms((1, 1, 4, 4, 1))[1][i][2:4]) for i in np.argmax(m6, axis=1)}
    assert got == {(0, 0), (0, 1), (1, 0), (0, 2), (1, 1), (2, 0)}
    over = dct_dictionary((5, 5, 4, 4, 3), 2400)
    assert over.n_atoms == 2400 and over.patch == (5, 5, 4, 4, 3)
    np.testing.assert_allclose(np.linalg.norm(over.atoms, axis=0), 1, atol=1e-5)


def _best_k_term_dct(data, p, t):
    """Independent reference for OMP on an orthonormal DCT: per non-overlapping p x p patch, the t
    largest scipy.fft.dctn coefficients (over V, U, P, P; then the colour basis) kept, the rest
    zeroed, transformed back with idctn; negatives clipped as evaluate_dictionary does."""
    from scipy.fft import dctn, idctn

    colour = np.array([[1, 1, 1], [1, 0, -1], [1, -2, 1]]) / np.sqrt([[3], [2], [6]])
    x = data.astype(np.float64)
    out = np.zeros_like(x)
    for y0 in range(0, x.shape[2], p):
        for x0 in range(0, x.shape[3], p):
            block = x[:, :, y0:y0 + p, x0:x0 + p]
            coef = dctn(block, axes=(0, 1, 2, 3), norm="ortho") @ colour.T
            keep = np.zeros(coef.size, bool)
            keep[np.argsort(np.abs(coef).ravel())[::-1][:t]] = True
            coef = np.where(keep.reshape(coef.shape), coef, 0)
            out[:, :, y0:y0 + p, x0:x0 + p] = idctn(coef @ colour, axes=(0, 1, 2, 3), norm="ortho")
    return np.maximum(out, 0)


def test_evaluate_matches_an_independent_best_k_term_dct_approximation():
    """Reference: _best_k_term_dct (scipy.fft.dctn). OMP with t atoms of an orthonormal basis keeps the
    t largest coefficients, so evaluate_dictionary's error with the complete DCT and non-overlapping
    patches must be the best t-term approximation's, computed without lfproc; a complete basis at
    sparsity n reproduces the light field exactly."""
    from lfproc.metrics import pu21_psnr

    lf = synthesize("layers", size=(16, 16), views=3, random_state=2)
    small = lf.data[:, :, 4:12, 4:12]
    full = dct_dictionary((3, 3, 1, 1, 3))
    r = evaluate_dictionary(full, [small], n_nonzero_coefs=full.n, compare_dct=False)
    assert r["relative_error"] < 1e-5
    d = dct_dictionary((3, 3, 4, 4, 3))  # complete: 432 atoms
    r10 = evaluate_dictionary(d, [lf], n_nonzero_coefs=10, stride=4)
    ref = _best_k_term_dct(lf.data, 4, 10)
    truth = lf.data.astype(np.float64)
    expected = np.linalg.norm(ref - truth) / np.linalg.norm(truth)
    assert 0.1 < expected < 0.9  # a real approximation, neither exact nor empty (0.453)
    assert r10["relative_error"] == pytest.approx(expected, rel=1e-4)
    assert r10["dct_relative_error"] == pytest.approx(expected, rel=1e-4)
    expected_pu21 = pu21_psnr(ref.astype(np.float32), lf.data, peak_luminance=1000.0, channel_axis=-1)
    assert r10["pu21_psnr_db"] == pytest.approx(expected_pu21, abs=0.05)
    # fewer atoms, larger error (the same reference at 3 atoms)
    r3 = evaluate_dictionary(d, [lf], n_nonzero_coefs=3, stride=4, compare_dct=False)
    expected3 = np.linalg.norm(_best_k_term_dct(lf.data, 4, 3) - truth) / np.linalg.norm(truth)
    assert r3["relative_error"] == pytest.approx(expected3, rel=1e-4) and expected3 > expected


@pytest.mark.slow  # two K-SVD trainings
def test_train_tiny_dictionary_beats_nothing_and_records_provenance():
    lf = synthesize("lamps", size=(40, 40), views=5, random_state=4)
    d = train_dictionary([lf], preset="tiny", atoms=200, patches=1500, max_iter=3, random_state=5, command="test")
    again = train_dictionary([lf], preset="tiny", atoms=200, patches=1500, max_iter=3, random_state=5, command="test")
    np.testing.assert_array_equal(d.atoms, again.atoms)  # seeded end to end
    assert d.patch == (5, 5, 4, 4, 3) and d.n_atoms == 200 and d.preset == "tiny"
    prov = d.provenance
    assert prov["seed"] == 5 and prov["training_patches"] == 1500 and prov["iterations"] == 3
    assert prov["errors"][-1] <= prov["errors"][0] and 0 < prov["final_relative_error"] < prov["errors"][0]


# -- CLI -----------------------------------------------------------------------------------------

def _cli(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_training_files_are_named_in_the_provenance(tmp_path, capsys):
    """A file's path is recorded, with the light field's own source (here lfproc synth's scene)."""
    lf_path = tmp_path / "scene.exr"
    assert main(["synth", "-o", str(lf_path), "--scene", "layers", "--size", "48", "48", "--seed", "4"]) == 0
    capsys.readouterr()
    out = tmp_path / "f.npz"
    code, _, err = _cli(["dictionary", "train", str(lf_path), "--preset", "tiny", "--atoms", "60", "--patches", "300",
                         "--iterations", "1", "-o", str(out)], capsys)
    assert code == 0, err
    code, stdout, _ = _cli(["dictionary", "info", str(out), "--json"], capsys)
    assert json.loads(stdout)["data"]["files"] == [f"{lf_path} (synth:layers)"]


def test_train_sources_must_name_every_light_field():
    lf = np.ones((5, 5, 16, 16, 3), np.float32)
    with pytest.raises(InputError, match=r"sources: expected one name per light field \(1\), got 2"):
        train_dictionary([lf], preset="tiny", sources=["a.exr", "b.exr"])


def test_cli_train_info_eval_preview(tmp_path, capsys):
    lf_path = tmp_path / "scene.exr"
    assert main(["synth", "-o", str(lf_path), "--scene", "window", "--size", "32", "32", "--seed", "2"]) == 0
    capsys.readouterr()
    out = tmp_path / "d.npz"
    code, stdout, err = _cli(["dictionary", "train", "--synthetic", "--preset", "tiny", "--atoms", "150",
                              "--patches", "1200", "--iterations", "2", "--seed", "3", "-o", str(out), "--json"],
                             capsys)
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["atoms"] == 150 and doc["patch"] == [5, 5, 4, 4, 3] and doc["training_patches"] == 1200
    assert not (tmp_path / "d.npz.ckpt").exists()  # the default checkpoint folder is removed at the end
    code, stdout, _ = _cli(["dictionary", "info", str(out), "--json"], capsys)
    info = json.loads(stdout)
    assert code == 0 and info["n"] == 1200 and info["sparsity"] == 6 and info["preset"] == "tiny"
    assert info["command"] == ("lfproc dictionary train --synthetic --preset tiny --atoms 150 --iterations 2 "
                               "--patches 1200 --seed 3")
    code, stdout, err = _cli(["dictionary", "eval", str(out), str(lf_path), "--json"], capsys)
    assert code == 0, err
    ev = json.loads(stdout)
    for key in ("pu21_psnr_db", "relative_error", "dct_pu21_psnr_db", "dct_relative_error"):
        assert np.isfinite(ev[key])
    assert 0 < ev["relative_error"] < 1
    png = tmp_path / "atoms.png"
    code, stdout, err = _cli(["preview", str(out), "-o", str(png), "--json"], capsys)
    assert code == 0, err
    from PIL import Image

    with Image.open(png) as im:
        assert im.size[0] > 100 and np.asarray(im).std() > 10  # a picture, not a blank


@pytest.mark.parametrize("argv, match", [
    (["dictionary", "train", "--preset", "huge", "--synthetic", "-o", "{tmp}/x.npz"], "preset"),
    (["dictionary", "train", "-o", "{tmp}/x.npz"], "no training data"),
    (["dictionary", "train", "{tmp}/lf3.exr", "--preset", "tiny", "-o", "{tmp}/x.npz"], "3 x 3 views"),
    (["dictionary", "train", "{tmp}/lf3.exr", "--preset", "tiny", "--patch", "3,3,40,40,3", "-o", "{tmp}/x.npz"],
     "smaller than"),
    (["dictionary", "info", "{tmp}/nothing.npz"], "no such dictionary"),
    (["dictionary", "info", "{tmp}/lf3.exr"], "not an lfproc dictionary"),
    (["dictionary", "eval", "{tmp}/nothing.npz", "{tmp}/lf3.exr"], "no such dictionary"),
])
def test_cli_dictionary_errors(tmp_path, capsys, argv, match):
    lf3 = tmp_path / "lf3.exr"
    main(["synth", "-o", str(lf3), "--size", "24", "24", "--views", "3"])
    capsys.readouterr()
    code, out, err = _cli([a.replace("{tmp}", str(tmp_path)) for a in argv], capsys)
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert pytest.importorskip("re").search(match, err), err
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow  # killed subprocess
def test_cli_train_killed_then_resumed_gives_the_uninterrupted_dictionary(tmp_path, kill_when):
    base = [sys.executable, "-m", "lfproc.cli.main", "dictionary", "train", "--synthetic", "--preset", "tiny",
            "--atoms", "150", "--patches", "1500", "--iterations", "4", "--seed", "9"]
    env = {**os.environ, "LFPROC_PROGRESS": "0", "OPENBLAS_NUM_THREADS": "1"}
    killed = tmp_path / "k.npz"
    ckpt = tmp_path / "k.npz.ckpt" / "ksvd-checkpoint.npz"
    kill_when(base + ["-o", str(killed)], ckpt.exists, timeout_s=120, env={"OPENBLAS_NUM_THREADS": "1"}, poll_s=0.05)
    assert ckpt.exists() and not killed.exists(), "the run should have been killed after its first iteration"
    subprocess.run(base + ["-o", str(killed)], env=env, check=True)
    straight = tmp_path / "s.npz"
    subprocess.run(base + ["-o", str(straight)], env=env, check=True)
    np.testing.assert_array_equal(load_dictionary(killed).atoms, load_dictionary(straight).atoms)


def test_training_sources_files_view_folders_and_datasets(tmp_path):
    from lfproc.dictionary._patches import collect_lightfields
    from lfproc.io import write_lightfield

    lf = synthesize("layers", size=(16, 16), views=5, random_state=1)
    ds = tmp_path / "dataset"
    for name in ("a", "b"):
        (ds / "scenes" / name).mkdir(parents=True)
        write_lightfield(lf, ds / "scenes" / name / "hdr.exr")
    (ds / "manifest.json").write_text("[]")
    single = write_lightfield(lf, tmp_path / "one.exr")
    found = collect_lightfields([ds, single])
    assert [p.relative_to(tmp_path).as_posix() for p in found] == ["dataset/scenes/a/hdr.exr",
                                                                   "dataset/scenes/b/hdr.exr", "one.exr"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no light fields"):
        collect_lightfields([tmp_path / "empty"])


# -- the shipped default ---------------------------------------------------------------------------

def test_shipped_default_dictionary_is_described(capsys):
    from lfproc.dictionary import PRESETS
    from lfproc.dictionary._files import shipped_path

    path = shipped_path("default")
    assert path.stat().st_size <= 25_000_000
    code, out, err = _cli(["dictionary", "info", "default", "--json"], capsys)
    assert code == 0, err
    info = json.loads(out)
    p = PRESETS["default"]
    assert info["atoms"] == p.atoms and info["n"] == 4800 and info["patch"] == list(p.patch)
    assert info["sparsity"] == p.sparsity and info["preset"] == "default" and info["training_patches"] == p.patches
    assert info["command"] == "lfproc dictionary train --synthetic --preset default --seed 0"
    assert 0 < info["final_relative_error"] < 0.2


@pytest.mark.slow  # real HDR photographs
def test_shipped_default_beats_dct_on_unseen_hdr_photographs(shared_data):
    """Light fields the dictionary never saw: lfproc synth scenes textured with real HDR photographs."""
    photos = sorted((shared_data / "hdr").glob("ScanLines_*.exr"))[:2]
    if not photos:
        pytest.skip("no ScanLines_*.exr HDR photographs in the shared data")
    lfs = [synthesize(kind, size=(64, 64), views=5, baseline_px=1.0, textures=[p], random_state=9100 + i)
           for i, (kind, p) in enumerate(zip(("window", "layers"), photos))]
    r = evaluate_dictionary("default", lfs, n_nonzero_coefs=10)
    assert r["pu21_psnr_db"] >= r["dct_pu21_psnr_db"] + 1.0, r
    assert r["relative_error"] < r["dct_relative_error"]
