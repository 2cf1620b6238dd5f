"""`discover` streamed (issue 25): the data pass folds each window's filtered rows into moments
(per fold and joint the triangular factor over the joint's columns; in the final pass lagged
products for the effective sample count),
so memory does not grow with the log.

* the moments against plain numpy on random rows fed in uneven chunks: the fit (numpy
  ``lstsq``), per-joint residual sums, out-of-fold residuals, and the effective sample count
  (the FFT autocorrelation of the residual numpy computes);
* a log read in chunks of 1500 samples (so streamed: several windows, chunked parallel
  filter, chunked held-out predictions) against the same log in one chunk (preprocessed
  whole): the same named set, values to 1e-9;
* several files streamed against the same files each preprocessed whole in memory and cut by
  ``split_time``, given to ``discover`` as segments.
"""
from __future__ import annotations

import numpy as np

from kindyngen.measured.discovery import discover
from kindyngen.measured.discovery_data import Moments, PassResult, effective_samples, layout_of, make_block
from kindyngen.measured.discovery_fit import Problem
from kindyngen.measured.effect_columns import coulomb_eps
from kindyngen.measured.discrepancy import DiscrepancyRequest, run_discrepancy
from kindyngen.measured.log_formats import joint_names_of, read_any
from kindyngen.measured.log_preparing import preprocess, split_time
from kindyngen.readers.yaml_description import load_robot
from tests.measured.test_discover_issue24 import write_log


def _problem(A, r, fold_of, folds, chunks, n, lags=32):
    """Moments of compact rows (a dense block of 2 columns, the tilt's, and a per-joint block) fed
    in ``chunks``, and their Problem; the same rows in the full layout (m, n, 2 + n)."""
    blocks = [make_block("base_tilt", n), make_block("torque_offset", n)]
    layout = layout_of(blocks, n)
    moments = Moments(n, layout.w, folds, lags, signals=True)
    start = 0
    for size in chunks:
        rows = slice(start, start + size)
        moments.add(fold_of[rows], A[rows], r[rows], r[rows], np.zeros((size, n, 5)))
        start += size
    assert start == len(r)
    result = PassResult(moments, layout, np.zeros(n), [], (), len(r))
    p = layout.p
    full = np.zeros((len(r), n, p))
    full[:, :, :2] = A[:, :, :2]
    for j in range(n):
        full[:, j, 2 + j] = A[:, j, 2]
    return Problem(result, (np.full(p, -np.inf), np.full(p, np.inf))), full


def test_moments_equal_plain_numpy():
    m, n, folds = 2000, 3, 5
    rng = np.random.default_rng(0)
    A = rng.standard_normal((m, n, 3))
    # noise correlated over a few samples (a moving average): the lags matter
    e = np.apply_along_axis(lambda x: np.convolve(x, np.ones(4) / 4, "same"), 0, rng.standard_normal((m, n)))
    fold_of = np.minimum((np.arange(m) * folds) // m, folds - 1)
    problem, full = _problem(A, np.zeros((m, n)), fold_of, folds, (m,), n)
    theta = rng.standard_normal(problem.p)
    r = full @ theta + 0.1 * e
    # uneven chunks, across fold boundaries
    problem, full = _problem(A, r, fold_of, folds, (7, 300, 1, 450, 33, 1209), n)
    fit = problem.fit(np.arange(problem.p))
    # plain numpy: the stacked least squares, its residual, the out-of-fold residuals
    A2, r2 = full.reshape(m * n, -1), r.reshape(-1)
    coef = np.linalg.lstsq(A2, r2, rcond=None)[0]
    residual = r - full @ coef
    np.testing.assert_allclose(problem.raw(fit["idx"], fit["theta"]), coef, rtol=1e-10)
    np.testing.assert_allclose(fit["joint_rss"], np.sum(residual ** 2, axis=0), rtol=1e-10)
    oof = np.empty_like(r)
    for k in range(folds):
        out = fold_of == k
        c = np.linalg.lstsq(full[~out].reshape(-1, problem.p), r[~out].reshape(-1), rcond=None)[0]
        oof[out] = r[out] - full[out] @ c
    np.testing.assert_allclose(fit["heldout"], np.sqrt(np.mean(oof ** 2, axis=0)), rtol=1e-10)
    n_eff, exact = problem.effective_samples(fit)
    assert exact
    np.testing.assert_allclose(n_eff, effective_samples(residual), rtol=1e-9)
    assert np.all(n_eff < 0.6 * m)                     # the moving average is seen


def test_a_residual_correlated_beyond_the_folded_lags_is_flagged():
    m, n = 3000, 2
    rng = np.random.default_rng(1)
    A = rng.standard_normal((m, n, 3))
    r = np.cumsum(rng.standard_normal((m, n)), axis=0)          # a random walk: correlated for long
    problem, _ = _problem(A, r, np.minimum((np.arange(m) * 2) // m, 1), 2, (m,), n)
    _, exact = problem.effective_samples(problem.fit(np.zeros(0, int)))
    assert not exact


def _close(a, b, rtol=1e-9):
    assert a.effects == b.effects and a.fitted == b.fitted, (a.effects, b.effects)
    assert a.values.keys() == b.values.keys()
    for name in a.values:
        assert abs(a.values[name] - b.values[name]) <= rtol * max(abs(b.values[name]), 1e-12), name
    np.testing.assert_allclose(a.rms_after, b.rms_after, rtol=rtol)
    np.testing.assert_allclose(a.noise_floor, b.noise_floor, rtol=rtol)
    np.testing.assert_allclose(a.n_eff, b.n_eff, rtol=rtol)


def test_small_chunks_give_the_result_of_one_chunk(tmp_path):
    log = write_log(tmp_path / "log.npz", "lwr4", ("coulomb_friction", "viscous_friction"))
    request = DiscrepancyRequest("robots/lwr4.yaml", (log,))
    whole = run_discrepancy(request)
    chunked = run_discrepancy(DiscrepancyRequest("robots/lwr4.yaml", (log,), chunk_rows=1500))
    assert any("streamed in chunks of 1500" in note for note in chunked.preprocessing_notes)
    assert not any("streamed" in note for note in whole.preprocessing_notes)
    assert set(whole.discovery.effects) == {"coulomb_friction", "viscous_friction"}
    _close(chunked.discovery, whole.discovery)
    np.testing.assert_allclose(chunked.rms_after, whole.rms_after, rtol=1e-9)
    np.testing.assert_allclose(chunked.rms_before, whole.rms_before, rtol=1e-9)
    assert chunked.samples == whole.samples


def test_files_streamed_equal_the_files_read_whole(tmp_path):
    logs = [write_log(tmp_path / f"{k}.npz", "lwr4", ("viscous_friction",), seed=k) for k in (1, 2, 3)]
    streamed = run_discrepancy(DiscrepancyRequest("robots/lwr4.yaml", tuple(logs), chunk_rows=1500)).discovery
    model = load_robot("robots/lwr4.yaml")
    train = []
    for log in logs:
        segments = preprocess(read_any(log, model.n, joint_names_of(model)))
        train += split_time(segments, 0.7)[0]
    whole = discover(model, train, eps=coulomb_eps(model))
    assert streamed.effects == ("viscous_friction",)
    _close(streamed, whole)
