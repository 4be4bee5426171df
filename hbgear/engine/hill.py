r"""Hill's method: the central Floquet exponents of the quadratic Hill eigenproblem.

With ``mu = lam / w`` (``w`` the base frequency) the linearised harmonic-balance problem is

    P(mu) v = (A0 + mu A1 + mu^2 A2) v = 0,    A0 = J,  A1 = w D1,  A2 = w^2 D2

(:meth:`hbgear.engine.hb.HarmonicBalance.hill_matrices`), of size ``N = n (2H+1)``. Its ``2N``
eigenvalues come in families ``mu + i k`` (copies: the same Floquet multiplier
``exp(2 pi mu)``); of every family the member whose eigenvector is most concentrated on the
central harmonics is the Floquet exponent (Lazarus & Thomas 2010). Two ways to get them, with
the same result:

- **dense** (:func:`dense_central`): all eigenpairs of the companion linearisation, batched over
  points (one stacked :func:`numpy.linalg.eig`), then :func:`select_central`: the candidates
  sorted by ``|centre|`` (:func:`harmonic_centre`), a copy of an exponent already taken
  skipped, until ``2n`` are found.
- **refined** (:func:`refined_central_batch`, :func:`refined_central`): the same selection on
  the Galerkin sub-problem of the low harmonics ``|k| <= Hs`` (its rows and columns; small and
  cheap) gives one seed per family; each is refined on the full problem by inverse iteration
  with the Rayleigh functional (quadratic convergence, one solve per step), then walked along
  its family (``mu -> mu +- i``, eigenvector shifted by one harmonic) while ``|centre|``
  decreases: the centre falls by one per copy, so a local minimum along the family is the
  family's most central member, the one the dense selection keeps. A point is settled this way
  only if every refinement converged (a step below :data:`STEP_TOL` and a backward error below
  :data:`BACKWARD_TOL`) onto the expected copy and ``2n`` families with distinct multipliers
  were found; otherwise the dense way decides (:func:`central_exponents`). Along a branch most
  points take their seeds from a settled neighbour's families instead of their own
  sub-problem (:func:`neighbour_seeded_central`), under the same acceptance test.

Copies are recognised by their multiplier (to ``copy_tol``) and, for a real multiplier, as
conjugates: the two members ``a +- i/2`` of a real negative multiplier's family (or ``a +- i k``
of a real positive one) are exact conjugates, and the truncation can move their multipliers
apart by more than ``copy_tol`` (1e-6 to 1e-5 at H = 4..8 in a parametric tongue, ~1e-6 at
H = 32 near the tongue of the NLTV pair), which used to let one family be taken twice and
another be missed.

With a free mean coordinate (reaction boundary) the exponent 0 is a Jordan block (``u = const``,
``u = t``); the (at most two) exponents within ``zero_tol`` of 0 are dropped.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import scipy.linalg
from threadpoolctl import ThreadpoolController

__all__ = [
    "dense_central",
    "harmonic_centre",
    "hill_quadratic",
    "refined_central",
    "refined_central_batch",
    "neighbour_seeded_central",
    "select_central",
    "central_exponents",
]

#: Above this many unknowns ``N = n (2H+1)`` the Hill matrices are computed one point at a time
#: and a point the batched refinement leaves unsettled gets a second, single-point refinement
#: before the dense way (below it the stacked dense eigen-decomposition is the cheaper rescue).
REFINE_MIN_SIZE = 48

#: Half-width of the harmonic window of the sub-problem that seeds the refinement.
SEED_HARMONICS = 6

#: A seed whose multiplier is within this (relative) of a family already found is not refined:
#: in the small sub-problem copies differ by up to ~1e-4 (more at low speeds, where a seed
#: that slips through only costs a refinement that lands on a member already found).
SEED_COPY_TOL = 1e-3

#: The refinement stops after a step below this (relative to ``max(1, |mu|)``): convergence is
#: quadratic, so the exponent is then exact to ~``STEP_TOL^2`` (the tests see <= 1e-11 relative
#: between the multipliers of the refined and the dense ways).
STEP_TOL = 1e-7

#: Real offset of the two restarts of a seed whose refinement does not converge (it sits
#: between two exponents ``a1 + i b``, ``a2 + i b``, e.g. a split real negative pair that the
#: sub-problem still sees as one complex pair: ``|a1 - a2|`` ~ 0.07 at 3800 rpm on the NLTV pair).
SPLIT_OFFSET = 0.05

#: A seed whose refinement fails while ``Im mu`` is within this of a multiple of 1/2 is first
#: retried as two seeds on that line, ``Re mu -+ SPLIT_REAL_OFFSET + i k/2``, kept only if both land
#: on real multipliers' families: the sub-problem merged two real multipliers into one complex
#: pair (at 5000 rpm on the 8-DOF NLTV pair -0.742 and -0.599, exponents -0.0475 + i/2 and
#: -0.0815 + i/2, seeded once at -0.0645 + 3.5251 i; the offsets of :data:`SPLIT_OFFSET` off the
#: line land near -0.033 + 3.527 i, a copy of a complex family). On the line, two starts either
#: side of the midpoint are each nearer their own exponent whatever the split.
SPLIT_REAL_WINDOW = 0.05
SPLIT_REAL_OFFSET = 0.02

#: Points per stacked refinement: about this many bytes per stack of complex pencils (3 points at
#: N = 130, all of a Duffing curve at N = 15). On the NLTV pair's 2406-point curve (N = 130) the
#: Hill exponents took 12.1 s with 3 points per stack, 15.3 s with 7 and 15.1 s with 1 (medians
#: of three alternated runs): larger stacks only add memory traffic, smaller ones call overhead.
BATCH_BYTES = 1e6

_BLAS_CONTROLLER: list = []


def single_thread_blas():
    """Context limiting BLAS to one thread; the controller scans the libraries once (a fresh
    ``threadpool_limits`` rescans them: ~1 ms per call, more than a small eigenproblem)."""
    if not _BLAS_CONTROLLER:
        _BLAS_CONTROLLER.append(ThreadpoolController())
    return _BLAS_CONTROLLER[0].limit(limits=1, user_api="blas")


# ============================================================================ the matrices

_PENCIL_FUNCTIONS: dict = {}

#: Points per vmapped Hill-matrix call: the largest power of two (at most 256) whose stacked
#: matrices fit in about this many bytes (8 points at N = 130, 64 at N = 42, 256 at N = 15). At
#: N = 130 one call of 8 points took 0.22 ms a point, one of 32 0.31 ms, one call per point
#: 0.49 ms; the 167 points of the Duffing curve (N = 15) 2.1 ms in chunks of 32, 0.97 ms in one
#: of 256.
PENCIL_CHUNK_BYTES = 4e6


def _pencil_chunk(size: int) -> int:
    """Points per vmapped call for pencils of `size` unknowns (see :data:`PENCIL_CHUNK_BYTES`)."""
    fit = max(1, int(PENCIL_CHUNK_BYTES // (24.0 * size * size)))
    return min(256, 1 << (fit.bit_length() - 1))


def _pencil_function(hb, batched: bool):
    """The jitted ``(z, p, system, prepared) -> (A0, A1, A2)`` stacked (vmapped over ``z, p`` if
    `batched`): :meth:`~hbgear.engine.hb.HarmonicBalance.hill_matrices` scaled by ``w``, ``w^2``
    in the compiled program, so its output is the array the refinement reads (no copies)."""
    key = (hb, batched)
    if key not in _PENCIL_FUNCTIONS:
        import jax
        import jax.numpy as jnp

        from .typed_jit import typed_jit

        def pencil(z, p, system, prepared):
            a0, d1, d2 = hb._hill_matrices_jit(z, p, system, prepared)
            w = hb.base_frequency(system, p)
            return jnp.stack([a0, w * d1, (w * w) * d2])

        from .persistent import persistent

        compiled = typed_jit(jax.vmap(pencil, in_axes=(0, 0, None, None)) if batched else pencil)
        # all it closes over is `hb` (frozen settings): its traced program may be kept on disk
        _PENCIL_FUNCTIONS[key] = persistent(compiled, "hill-pencils" if batched else "hill-pencil",
                                            ("engine.hill._pencil_function", hb, batched))
    return _PENCIL_FUNCTIONS[key]


def hill_pencils(hb, zs, ps, system, prepared=None):
    """The stacked Hill matrices ``(A0, A1, A2)`` of ``P(mu)`` at the points ``(zs[i], ps[i])``.

    One jitted call per chunk of :func:`_pencil_chunk` points, vmapped (the last chunk padded,
    so one compilation serves every curve length; a single point is one unbatched call), the
    discretisation prepared once (or given: `prepared`, :meth:`~hbgear.engine.hb.HarmonicBalance.prepare`).

    **Returns:** ``(pencils, w)``: a list of read-only arrays ``(k, 3, N, N)`` (``A0 = J``,
    ``A1 = w D1``, ``A2 = w^2 D2``, scaled), ``k`` points each, in order, and ``(m,)`` the base
    frequency of each point.
    """
    import jax  # device_put, not jnp.asarray: that compiles a small program per shape

    zs = np.atleast_2d(np.asarray(zs, dtype=float))
    ps = np.atleast_1d(np.asarray(ps, dtype=float))
    m = len(ps)
    w = np.array([float(hb.base_frequency(system, p)) for p in ps])
    prepared = hb.prepare(system) if prepared is None else prepared
    if m == 1:
        return [np.asarray(_pencil_function(hb, False)(jax.device_put(zs[0]), ps[0], system, prepared))[None]], w
    fn, chunk = _pencil_function(hb, True), _pencil_chunk(hb.size)
    out = []
    for lo in range(0, m, chunk):
        idx = np.minimum(np.arange(lo, lo + chunk), m - 1)
        out.append(np.asarray(fn(*jax.device_put((zs[idx], ps[idx])), system, prepared))[:min(chunk, m - lo)])
    return out, w


def hill_quadratic(hb, zs, ps, system):
    """``(A0, A1, A2, w)`` of ``P(mu)`` at the points ``(zs[i], ps[i])``: shapes ``(m, N, N)``, ``(m,)``
    (from :func:`hill_pencils`)."""
    parts, w = hill_pencils(hb, zs, ps, system)
    pencils = np.concatenate(parts) if len(parts) > 1 else parts[0]
    return pencils[:, 0], pencils[:, 1], pencils[:, 2], w


# ============================================================================ selection


def harmonic_centre(vectors: np.ndarray, ndof: int, harmonics: int) -> np.ndarray:
    """Energy-weighted mean signed harmonic index of each eigenvector (columns).

    `vectors`: shape ``(..., N, k)`` in the real basis ``[a0, a1, b1, a2, b2, ...]`` per
    coordinate; ``a cos + b sin`` carries ``|a - i b|^2 / 4`` on ``e^{+ik tau}`` and
    ``|a + i b|^2 / 4`` on ``e^{-ik tau}``. Returns shape ``(..., k)``.
    """
    block = 2 * harmonics + 1
    lead = vectors.shape[:-2]
    v = vectors.reshape(lead + (ndof, block, vectors.shape[-1]))
    a, b = v[..., 1::2, :], v[..., 2::2, :]
    plus = np.sum(np.abs(a - 1j * b) ** 2, axis=-3) / 4.0  # (..., H, k)
    minus = np.sum(np.abs(a + 1j * b) ** 2, axis=-3) / 4.0
    zero = np.sum(np.abs(v[..., 0, :]) ** 2, axis=-2)
    k = np.arange(1, harmonics + 1)[:, None]
    total = zero + plus.sum(axis=-2) + minus.sum(axis=-2)
    return (k * (plus - minus)).sum(axis=-2) / np.maximum(total, 1e-300)


#: Tie-break of the centrality: an eigenpair and its conjugate have exactly opposite centres,
#: and for a real negative multiplier they are two copies (``a +- i/2``) of one family; the
#: one with ``Im mu >= 0`` is preferred, so the choice does not depend on rounding.
_TIE = 1e-9


def centrality(mu, centre):
    """Sort key of the selection: ``|centre|``, ties between conjugates to ``Im mu >= 0``."""
    return np.abs(centre) - _TIE * np.where(np.imag(mu) >= 0.0, 1.0, -1.0)


#: ``|2 Im mu - round(2 Im mu)|`` below this: the family of ``mu`` is its own conjugate (a real
#: multiplier), so the conjugate eigenpair is one of its copies however far the truncated
#: problem has moved the two apart (at H = 32 their multipliers can differ by more than 1e-6).
SELF_CONJUGATE_TOL = 1e-5


def _is_self_conjugate(mu: complex, tol: float = SELF_CONJUGATE_TOL) -> bool:
    """``mu`` and ``conj(mu)`` in one family: ``Im mu`` a multiple of 1/2."""
    return abs(2.0 * mu.imag - round(2.0 * mu.imag)) <= tol


def _is_copy(mu_i, m_i, taken_mu, taken_mult, copy_tol) -> bool:
    """``mu_i`` a copy of a taken exponent: the same multiplier (to `copy_tol`), or the exact
    conjugate of a taken exponent of a self-conjugate family."""
    for mu_j, m_j in zip(taken_mu, taken_mult):
        if abs(m_i - m_j) <= copy_tol * max(1.0, abs(m_j)):
            return True
        if abs(mu_i - np.conj(mu_j)) <= 1e-12 * max(1.0, abs(mu_j)) and _is_self_conjugate(mu_j):
            return True
    return False


def _trivial(mu: np.ndarray, zero_tol: float) -> list[int]:
    """Indices of the (at most two) exponents within `zero_tol` of 0."""
    return [int(i) for i in np.argsort(np.abs(mu))[:2] if abs(mu[i]) < zero_tol]


def select_central(mu, centre, need: int, *, zero_tol: float | None = None, copy_tol: float = 1e-6):
    """Indices of the ``need`` central exponents among the candidates ``mu`` (one point).

    Candidates by increasing ``|centre|`` (:func:`centrality`); one whose multiplier ``exp(2 pi mu)`` equals (to
    `copy_tol`) one already taken is a copy and skipped, and so is the conjugate of a taken
    exponent of a self-conjugate family (the tie at half-integer centres of a real negative
    multiplier, where ``sigma +- i/2`` belong to one family, whatever their distance); if fewer
    than ``need`` are found, repeated multipliers are filled in from the skipped ones. With
    `zero_tol`, the (at most two) exponents within it of 0 are dropped first (and ``need``
    lowered by their number).

    **Returns:** ``(indices, trivial, filled)``: the picks, how many trivial exponents were
    dropped, and whether a skipped candidate had to be filled in.
    """
    mu = np.asarray(mu)
    mult = np.exp(2.0 * np.pi * mu)
    near_zero = _trivial(mu, zero_tol) if zero_tol is not None else []
    seen_mu, seen = list(mu[near_zero]), list(mult[near_zero])
    skip = set(near_zero)
    want = need - len(near_zero)
    taken: list[int] = []
    skipped: list[int] = []
    for i in np.argsort(centrality(mu, centre), kind="stable"):
        if len(taken) == want:
            break
        if i in skip:
            continue
        if _is_copy(mu[i], mult[i], seen_mu, seen, copy_tol):
            skipped.append(int(i))
            continue
        taken.append(int(i))
        seen_mu.append(mu[i])
        seen.append(mult[i])
    filled = False
    for i in skipped:  # genuinely repeated multipliers
        if len(taken) == want:
            break
        taken.append(i)
        filled = True
    return np.asarray(taken, dtype=int), len(near_zero), filled


# ============================================================================ dense


def _companion(a0, a1, a2):
    """``C = [[0, I], [-A2^-1 A0, -A2^-1 A1]]`` with ``C (v, mu v) = mu (v, mu v)``, batched."""
    m, size = a0.shape[0], a0.shape[-1]
    rhs = np.linalg.solve(a2, np.concatenate([a0, a1], axis=-1))
    comp = np.zeros((m, 2 * size, 2 * size))
    comp[:, :size, size:] = np.eye(size)
    comp[:, size:] = -rhs
    return comp


def dense_central(a0, a1, a2, ndof: int, harmonics: int, *, zero_tol=None, copy_tol: float = 1e-6):
    """Central exponents ``mu`` of every point (a list of arrays) from all eigenpairs."""
    with single_thread_blas():
        # threads only add synchronisation to eigenproblems this small
        mu, vec = np.linalg.eig(_companion(a0, a1, a2))
    size = a0.shape[-1]
    centre = harmonic_centre(vec[:, :size], ndof, harmonics)
    out = []
    for k in range(len(mu)):
        idx, _, _ = select_central(mu[k], centre[k], 2 * ndof, zero_tol=zero_tol, copy_tol=copy_tol)
        out.append(mu[k][idx])
    return out


# ============================================================================ refined


def _window(ndof: int, harmonics: int, seed: int) -> np.ndarray:
    """Indices of the harmonics ``0..seed`` (cos and sin) of every coordinate in the full vector."""
    block = 2 * harmonics + 1
    return (np.arange(ndof)[:, None] * block + np.arange(2 * seed + 1)[None]).ravel()


def _shift_harmonics(v: np.ndarray, ndof: int, harmonics: int, k) -> np.ndarray:
    """The eigenvector of the copy ``mu + i k`` from that of ``mu``: complex harmonic ``j`` of
    the periodic factor moves to ``j - k`` (``e^{(mu + ik) tau} p'(tau) = e^{mu tau} p(tau)``).

    `v`: one vector ``(N,)`` and an integer `k`, or a stack ``(m, N)`` and ``(m,)`` shifts."""
    block = 2 * harmonics + 1
    single = v.ndim == 1
    x = v.reshape(-1, ndof, block)
    shift = np.broadcast_to(np.asarray(k, dtype=int), x.shape[:1])
    c = np.empty(x.shape, dtype=complex)  # complex coefficients, index j + H
    c[..., harmonics] = x[..., 0]
    c[..., harmonics + 1 :] = (x[..., 1::2] - 1j * x[..., 2::2]) / 2.0
    c[..., harmonics - 1 :: -1] = (x[..., 1::2] + 1j * x[..., 2::2]) / 2.0
    source = np.arange(block)[None, :] + shift[:, None]  # new index i holds old index i + k
    inside = (source >= 0) & (source < block)
    c = np.take_along_axis(c, np.clip(source, 0, block - 1)[:, None, :], axis=-1) * inside[:, None, :]
    out = np.empty(x.shape, dtype=complex)
    out[..., 0] = c[..., harmonics]
    pos, neg = c[..., harmonics + 1 :], c[..., harmonics - 1 :: -1]
    out[..., 1::2] = pos + neg
    out[..., 2::2] = 1j * (pos - neg)
    return out.reshape(v.shape) if single else out.reshape(len(x), -1)


def _refine(a0, a1, a2, mu, v, *, tol=STEP_TOL, max_steps=8, fixed_steps=0):
    """Inverse iteration with the Rayleigh functional on one point's matrices ``(N, N)``:
    :func:`_batched_refine` with one seed (``v <- P(mu)^-1 P'(mu) v``, then ``mu`` the root of
    ``v^H P(mu) v = 0`` nearest the last one, until ``mu`` moves less than ``tol max(1, |mu|)``
    at a backward error below :data:`BACKWARD_TOL`); the first `fixed_steps` steps keep the
    shift (plain inverse iteration: picks the exponent nearest `mu` out of a close pair).
    Returns ``(mu, v, converged)``."""
    m, x, ok = _batched_refine(a0[None], a1[None], a2[None], np.zeros(1, dtype=int), np.array([mu], dtype=complex),
                               np.asarray(v, dtype=complex)[None], tol=tol, max_steps=max_steps, fixed_steps=fixed_steps)
    return complex(m[0]), x[0], bool(ok[0])


def _is_conjugate_copy(mu, k) -> bool:
    """The copy ``mu + i k`` is ``conj(mu)`` (``Im mu = -k/2``, a real multiplier's family): the
    conjugate eigenpair, known without a refinement, with the opposite centre."""
    return abs(2.0 * mu.imag + k) <= SELF_CONJUGATE_TOL


def _most_central_member(a0, a1, a2, mu, v, ndof, harmonics, *, max_walk=6, fixed_steps=0):
    """Refine ``(mu, v)`` and walk along its family to the member of least ``|centre|``.

    Returns ``(mu, centre)`` or ``None`` when a refinement does not converge or lands off the
    expected copy."""
    mu, v, ok = _refine(a0, a1, a2, mu, v, fixed_steps=fixed_steps)
    if not ok:
        return None
    c = float(harmonic_centre(v[:, None], ndof, harmonics)[0])
    for _ in range(max_walk):
        if abs(c) <= 0.25:  # a copy is one harmonic away: its |centre| is >= 0.75 > |c|
            return mu, c
        k = 1 if c > 0 else -1  # the copy mu + i k has centre c - k
        if _is_conjugate_copy(mu, k):
            nb_mu, nb_v, nb_c = np.conj(mu), np.conj(v), -c
        else:
            nb_mu, nb_v, ok = _refine(a0, a1, a2, mu + 1j * k, _shift_harmonics(v, ndof, harmonics, k))
            if not ok or abs(nb_mu - (mu + 1j * k)) > 0.25:
                return None
            nb_c = float(harmonic_centre(nb_v[:, None], ndof, harmonics)[0])
        if centrality(nb_mu, nb_c) >= centrality(mu, c):
            return mu, c
        mu, v, c = nb_mu, nb_v, nb_c
    return None


def refined_central(a0, a1, a2, ndof: int, harmonics: int, *, zero_tol=None, copy_tol: float = 1e-6,
                    seed_harmonics: int = SEED_HARMONICS):
    """Central exponents of one point (``(N, N)`` matrices) by refinement, or ``None``.

    See the module docstring. Seeds are taken by increasing centrality from the sub-problem's
    eigenpairs until ``2n`` families (less the trivial ones) are found; a seed whose
    multiplier is within ``SEED_COPY_TOL`` of a family already found is skipped, one that walks
    to a member already found counts once, and the conjugate of every complex family is added
    without a refinement (real matrices). ``None`` when not confident: a refinement failed or
    did not land on the expected copy, too many seeds were needed, or two families share a
    multiplier (to `copy_tol`).
    """
    seed = min(seed_harmonics, harmonics)
    win = _window(ndof, harmonics, seed)
    sub = [x[np.ix_(win, win)][None] for x in (a0, a1, a2)]
    with single_thread_blas():
        mu_s, vec_s = np.linalg.eig(_companion(*sub))
        mu_s, vec_s = mu_s[0], vec_s[0, : win.size]
        near_zero = set(_trivial(mu_s, zero_tol)) if zero_tol is not None else set()
        want = 2 * ndof - len(near_zero)
        found: list[complex] = []
        tries = 0
        for i in np.argsort(centrality(mu_s, harmonic_centre(vec_s, ndof, seed)), kind="stable"):
            if len(found) >= want or tries > 2 * want + 2:
                break
            m = np.exp(2.0 * np.pi * mu_s[i])
            if i in near_zero or any(abs(m - np.exp(2.0 * np.pi * f)) <= SEED_COPY_TOL * max(1.0, abs(m))
                                     for f in found):
                continue
            tries += 1
            v = np.zeros(a0.shape[0], dtype=complex)
            v[win] = vec_s[:, i]
            v /= np.linalg.norm(v)
            best = [_most_central_member(a0, a1, a2, mu_s[i], v, ndof, harmonics)]
            if best[0] is None and (line := _real_line(np.array([mu_s[i]]))[0]) is not None:
                # the seed may merge two real multipliers (SPLIT_REAL_WINDOW): a start on either side
                best = [_most_central_member(a0, a1, a2, line + d, v, ndof, harmonics, fixed_steps=2)
                        for d in (-SPLIT_REAL_OFFSET, SPLIT_REAL_OFFSET)]
                if not all(b is not None and _is_self_conjugate(b[0], 2 * SELF_CONJUGATE_TOL) for b in best):
                    best = [None]
            if best[0] is None:
                # the seed may sit between two close exponents (a complex pair of the sub-problem
                # that is a split real pair in the full problem): one start on either side
                best = [_most_central_member(a0, a1, a2, mu_s[i] + d, v, ndof, harmonics, fixed_steps=2)
                        for d in (-SPLIT_OFFSET, SPLIT_OFFSET)]
            if any(b is None for b in best):
                return None
            for mu_b, _ in best:
                if any(abs(mu_b - f) <= 1e-9 * max(1.0, abs(f)) for f in found):
                    continue  # a copy of a family already found (the sub-problem did not merge them)
                found.append(mu_b)
                if not _is_self_conjugate(mu_b):
                    found.append(np.conj(mu_b))
    return _distinct_families(found, want, copy_tol)


# ============================================================================ refined, batched


#: A refinement step counts as converged only if, besides a step below :data:`STEP_TOL`, the
#: eigenpair's backward error ``|P(mu) v| / ((|A0| + |mu| |A1| + |mu|^2 |A2|) |v|)`` (Frobenius
#: norms, ``|v| = 1``) is below this: the step test assumes quadratic convergence, and a slow
#: approach from a far seed passed it with the multipliers up to 3e-9 off the dense way's
#: (backward errors 1e-13 to 7e-13, where converged pairs are below 1.4e-14; Duffing curve, its
#: points in random order).
BACKWARD_TOL = 1e-13


def _batched_refine(a0, a1, a2, owner, mu, v, *, tol=STEP_TOL, max_steps=8, update="rayleigh", fixed_steps=0):
    """Inverse iteration for many seeds at once (seed ``s`` belongs to point ``owner[s]``): one
    stacked solve per step over the seeds not yet converged; the first `fixed_steps` steps keep
    the shifts. Converged: a step below ``tol max(1, |mu|)`` at a backward error below
    :data:`BACKWARD_TOL`. Returns ``(mu, v, converged)``.

    `update` of ``mu`` after the step ``x = P(mu)^-1 P'(mu) v`` (``|v| = 1``): ``"rayleigh"``,
    the root of ``x^H P(mu') x = 0`` nearest ``mu``, or ``"newton"``,
    ``mu' = mu - 1 / (v^H x)`` (nonlinear inverse iteration, Ruhe 1973: quadratic convergence
    to a simple exponent). Where two real exponents are about to merge into a complex pair
    (the nearly parallel eigenvectors of a super-harmonic resonance) the roots of the Rayleigh
    functional lie between them, off the real axis, and its iteration stalls there; the Newton
    update from a real seed stays real and converges to the exponent nearest the seed."""
    mu, v = mu.copy(), v.copy()
    converged = np.zeros(len(mu), dtype=bool)
    active = np.arange(len(mu))
    size = a0.shape[-1]
    # the real matrices of each seed's point, once: (seeds, 3, N, N); every product below is a real
    # matmul on the complex vectors' (re, im) columns (a real @ complex matmul copies the matrix to complex)
    stacked = np.stack([a0, a1, a2], axis=1)[owner]
    norms = np.sqrt(np.einsum("skij,skij->sk", stacked, stacked))  # |A0|, |A1|, |A2| (Frobenius)
    for step in range(max_steps):
        if active.size == 0:
            break
        c = stacked if active.size == len(stacked) else stacked[active]
        m, x = mu[active], v[active]
        coef = np.stack([np.ones_like(m), m, m * m], axis=1)[:, None, :]  # P(m) = A0 + m A1 + m^2 A2
        flat = c.reshape(len(c), 3, size * size)
        pencil = np.empty((len(c), size * size), dtype=complex)
        pencil.real = (coef.real @ flat)[:, 0]
        pencil.imag = (coef.imag @ flat)[:, 0]
        ax = (c[:, 1:] @ _as_columns(x)[:, None]).view(complex)[..., 0]  # A1 x, A2 x
        try:  # P(m) y = P'(m) x = (A1 + 2 m A2) x
            y = np.linalg.solve(pencil.reshape(-1, size, size), (ax[:, 0] + (2.0 * m)[:, None] * ax[:, 1])[..., None])
        except np.linalg.LinAlgError:  # an exactly singular pencil: leave these to the single-point way
            break
        y = y[..., 0]
        norm = np.linalg.norm(y, axis=1)
        if update == "newton":
            with np.errstate(divide="ignore", invalid="ignore"):
                new = m - 1.0 / np.sum(x.conj() * y, axis=1)
        bad = ~np.isfinite(norm) | (norm == 0.0)
        y = y / np.where(bad, 1.0, norm)[:, None]
        if step < fixed_steps:  # plain inverse iteration: the shift kept
            v[active] = np.where(bad[:, None], x, y)
            active = active[~bad]
            continue
        ay = (c @ _as_columns(y)[:, None]).view(complex)[..., 0]  # A0 y, A1 y, A2 y
        if update != "newton":
            qc, qb, qa = np.einsum("sn,skn->ks", y.conj(), ay)
            disc = np.sqrt(qb * qb - 4.0 * qa * qc + 0j)
            r1, r2 = (-qb + disc) / (2.0 * qa), (-qb - disc) / (2.0 * qa)
            new = np.where(np.abs(r1 - m) <= np.abs(r2 - m), r1, r2)
        bad |= ~np.isfinite(new)
        n = norms if active.size == len(norms) else norms[active]
        backward = np.linalg.norm(ay[:, 0] + new[:, None] * ay[:, 1] + (new * new)[:, None] * ay[:, 2], axis=1) / (
            n[:, 0] + np.abs(new) * n[:, 1] + np.abs(new) ** 2 * n[:, 2])
        done = (np.abs(new - m) <= tol * np.maximum(1.0, np.abs(new))) & (backward <= BACKWARD_TOL)
        mu[active], v[active] = new, y
        converged[active[done & ~bad]] = True
        active = active[~done & ~bad]
    return mu, v, converged


def _as_columns(x: np.ndarray) -> np.ndarray:
    """Complex vectors ``(s, N)`` as real ``(s, N, 2)`` (re, im) columns, without a copy."""
    return np.ascontiguousarray(x).view(float).reshape(x.shape + (2,))


def _batched_walk(a0, a1, a2, owner, mu, v, converged, ndof, harmonics, *, max_walk=4, update="rayleigh"):
    """:func:`_most_central_member`'s walk for refined seeds, batched: every seed with
    ``|centre| > 1/4`` has its neighbour copy towards the centre refined (one stacked solve per
    step); a seed moves there while the centrality falls. A seed is left unconverged when a
    neighbour does not converge onto the expected copy or the walk does not settle."""
    centre = harmonic_centre(v.T, ndof, harmonics) if len(mu) else np.zeros(0)
    open_ = np.flatnonzero(converged & (np.abs(centre) > 0.25))
    for _ in range(max_walk):
        if open_.size == 0:
            return mu, v, centre, converged
        k = np.where(centre[open_] > 0, 1, -1)
        conj = np.abs(2.0 * mu[open_].imag + k) <= SELF_CONJUGATE_TOL  # see _is_conjugate_copy
        nb_mu, nb_v = np.conj(mu[open_]), np.conj(v[open_])
        nb_c, nb_ok = -centre[open_], np.ones(open_.size, dtype=bool)
        other = np.flatnonzero(~conj)
        if other.size:
            s_other = open_[other]
            start = _shift_harmonics(v[s_other], ndof, harmonics, k[other])
            target = mu[s_other] + 1j * k[other]
            r_mu, r_v, r_ok = _batched_refine(a0, a1, a2, owner[s_other], target, start, update=update)
            nb_mu[other], nb_v[other] = r_mu, r_v
            nb_ok[other] = r_ok & (np.abs(r_mu - target) <= 0.25)
            nb_c[other] = harmonic_centre(r_v.T, ndof, harmonics)
        converged[open_[~nb_ok]] = False
        better = nb_ok & (centrality(nb_mu, nb_c) < centrality(mu[open_], centre[open_]))
        moved = open_[better]
        mu[moved], v[moved], centre[moved] = nb_mu[better], nb_v[better], nb_c[better]
        open_ = moved[np.abs(centre[moved]) > 0.25]
    converged[open_] = False
    return mu, v, centre, converged


def _real_line(mu):
    """``Re mu + i k/2`` for the exponents within :data:`SPLIT_REAL_WINDOW` of a multiple of 1/2, else ``None``."""
    mu = np.asarray(mu, dtype=complex)
    half = np.round(2.0 * mu.imag) / 2.0
    near = np.abs(mu.imag - half) <= SPLIT_REAL_WINDOW
    return [complex(x.real, h) if ok else None for x, h, ok in zip(mu, half, near)]


def _split_real_seeds(a0, a1, a2, owner, seed_mu, seed_v, mu, v, converged, ndof, harmonics):
    """The failed seeds near a real multiplier's line (:data:`SPLIT_REAL_WINDOW`) replaced by two
    starts on it, refined and walked (batched, the Newton update); a pair is kept converged only
    if both land on real multipliers' families. Returns ``(owner, mu, v, converged)``."""
    failed = np.flatnonzero(~converged)
    line = _real_line(seed_mu[failed])
    failed = np.asarray([f for f, x in zip(failed, line) if x is not None], dtype=int)
    if failed.size == 0:
        return owner, mu, v, converged
    centre = np.asarray([x for x in line if x is not None])
    starts = np.concatenate([centre - SPLIT_REAL_OFFSET, centre + SPLIT_REAL_OFFSET])
    pair_owner = np.concatenate([owner[failed], owner[failed]])
    pair_v = np.concatenate([seed_v[failed], seed_v[failed]])
    r_mu, r_v, r_ok = _batched_refine(a0, a1, a2, pair_owner, starts, pair_v, update="newton")
    r_mu, r_v, _, r_ok = _batched_walk(a0, a1, a2, pair_owner, r_mu, r_v, r_ok, ndof, harmonics, update="newton")
    r_ok &= np.abs(2.0 * r_mu.imag - np.round(2.0 * r_mu.imag)) <= 2 * SELF_CONJUGATE_TOL
    both = r_ok[: failed.size] & r_ok[failed.size :]
    r_ok = np.concatenate([both, both])
    keep = np.ones(len(mu), dtype=bool)
    keep[failed] = False
    return (np.concatenate([owner[keep], pair_owner]), np.concatenate([mu[keep], r_mu]),
            np.concatenate([v[keep], r_v]), np.concatenate([converged[keep], r_ok]))


def _batch_seed_harmonics(harmonics: int) -> int:
    """Seed window of the batched refinement: half the harmonics, at most SEED_HARMONICS."""
    return max(1, min(SEED_HARMONICS, harmonics // 2))


def _seed_picks(mu, mult, key, need: int, near_zero) -> list[int]:
    """The seed selection of one point in plain Python (lists): by increasing `key`, skipping
    the trivial ones and copies of a pick's multiplier to ``SEED_COPY_TOL``, then dropping a
    pick whose conjugate is a pick too (the conjugate family comes without a refinement)."""
    picks: list[int] = []
    for i in sorted(range(len(key)), key=key.__getitem__):
        if len(picks) == need:
            break
        if i in near_zero or any(abs(mult[i] - mult[j]) <= SEED_COPY_TOL * max(1.0, abs(mult[j])) for j in picks):
            continue
        picks.append(i)
    tol = 1e-9 * max([1.0] + [abs(mu[i]) for i in picks])
    return [i for i in picks
            if not (mu[i].imag < -tol and any(abs(mu[i].conjugate() - mu[j]) <= tol for j in picks))]


def _subproblem_seeds(a0, a1, a2, ndof: int, harmonics: int, zero_tol):
    """The seeds of every point from its sub-problem (:func:`_batch_seed_harmonics`), one stacked
    eigen-decomposition: ``(owner, mu, v, want)``, seed ``s`` of point ``owner[s]``, ``want[k]``
    the number of exponents point ``k`` needs (``2n`` less its trivial ones)."""
    m, size = a0.shape[0], a0.shape[-1]
    seed = _batch_seed_harmonics(harmonics)
    win = _window(ndof, harmonics, seed)
    mu_s, vec_s = np.linalg.eig(_companion(*(x[:, win][:, :, win] for x in (a0, a1, a2))))
    vec_s = vec_s[:, : win.size]
    key = centrality(mu_s, harmonic_centre(vec_s, ndof, seed)).tolist()
    mult_s = np.exp(2.0 * np.pi * mu_s).tolist()
    mu_list = mu_s.tolist()
    owner, picks_of, want = [], [], []
    for k in range(m):
        near_zero = _trivial(mu_s[k], zero_tol) if zero_tol is not None else []
        picks = _seed_picks(mu_list[k], mult_s[k], key[k], 2 * ndof - len(near_zero), set(near_zero))
        want.append(2 * ndof - len(near_zero))
        owner.extend([k] * len(picks))
        picks_of.extend(picks)
    owner, picks_of = np.asarray(owner, dtype=int), np.asarray(picks_of, dtype=int)
    v0 = np.zeros((len(owner), size), dtype=complex)
    if len(owner):
        v0[:, win] = vec_s[owner, :, picks_of]
        v0 /= np.linalg.norm(v0, axis=1, keepdims=True)
    return owner, mu_s[owner, picks_of], v0, want


def _settle_seeds(a0, a1, a2, owner, seed_mu, seed_v, want, ndof: int, harmonics: int, copy_tol: float,
                  update: str):
    """Refine, walk and (near a real multiplier's line) split the seeds of every point, stacked.

    **Returns:** ``(found, families)``: per point the exponents (``None`` where not settled,
    see :func:`refined_central_batch`), and per settled point its families' representatives
    ``(mu, v)`` (refined eigenpairs on their most central members, one per family and complex
    pair), which seed the neighbours of :func:`neighbour_seeded_central`."""
    m = len(want)
    mu, v, converged = _batched_refine(a0, a1, a2, owner, seed_mu, seed_v, update=update)
    mu, v, _, converged = _batched_walk(a0, a1, a2, owner, mu, v, converged, ndof, harmonics, update=update)
    owner, mu, v, converged = _split_real_seeds(a0, a1, a2, owner, seed_mu, seed_v, mu, v, converged, ndof,
                                                harmonics)
    settled = np.ones(m, dtype=bool)
    np.logical_and.at(settled, owner, converged)
    mu_list, owner_list = mu.tolist(), owner.tolist()
    found_of: list[list[complex]] = [[] for _ in range(m)]
    reps_of: list[list[int]] = [[] for _ in range(m)]
    for s, (k, x) in enumerate(zip(owner_list, mu_list)):
        found = found_of[k]
        if any(abs(x - f) <= 1e-9 * max(1.0, abs(f)) for f in found):
            continue  # two seeds walked to one member
        found.append(x)
        reps_of[k].append(s)
        if not _is_self_conjugate(x):
            found.append(x.conjugate())
    out: list = [None] * m
    families: list = [None] * m
    for k in range(m):
        if settled[k]:
            out[k] = _distinct_families(found_of[k], want[k], copy_tol)
            if out[k] is not None:
                families[k] = (mu[reps_of[k]], v[reps_of[k]])
    return out, families


def refined_central_batch(a0, a1, a2, ndof: int, harmonics: int, *, zero_tol=None, copy_tol: float = 1e-6,
                          update: str = "rayleigh", families: bool = False):
    """:func:`refined_central` for a stack of points: a list with ``None`` where a point is not
    settled this way (a refinement or a walk step did not converge onto the expected copy, or
    not ``2n`` distinct families were found). `update`: see :func:`_batched_refine`;
    `families`: also return the settled points' representatives (see :func:`_settle_seeds`).

    The seed sub-problems (:func:`_batch_seed_harmonics`) are one stacked eigen-decomposition,
    every refinement step and every walk step one stacked solve over all points: this removes
    the per-point call overhead that dominates small problems (Duffing, H = 7).
    """
    with single_thread_blas():
        owner, seed_mu, seed_v, want = _subproblem_seeds(a0, a1, a2, ndof, harmonics, zero_tol)
        out, reps = _settle_seeds(a0, a1, a2, owner, seed_mu, seed_v, want, ndof, harmonics, copy_tol, update)
    return (out, reps) if families else out


#: :func:`central_exponents` seeds one point in this many along a stack of consecutive points
#: from its own sub-problem and the others from the nearest such point's refined families (the
#: stacked eigen-decompositions of the seeds were ~30 % of Hill's time on the Duffing curve).
NEIGHBOUR_STRIDE = 4


def neighbour_seeded_central(a0, a1, a2, ndof: int, harmonics: int, *, copy_tol: float = 1e-6,
                             stride: int = NEIGHBOUR_STRIDE):
    """Central exponents of consecutive points of a branch, most of them seeded by a neighbour.

    Every `stride`-th point (and the last) is settled from its own sub-problem
    (:func:`refined_central_batch`); every other point's seeds are the refined families of the
    nearest such settled point, refined, walked and split on the point's own matrices
    (:func:`_settle_seeds`) and accepted by the same test (every refinement converged onto its
    expected copy, ``2n`` distinct families). A list with ``None`` where a point is not settled:
    :func:`central_exponents` then seeds it from its own sub-problem. Not for problems whose
    trivial exponents are dropped (their number may change from one point to the next).
    """
    m = a0.shape[0]
    anchors = np.unique(np.append(np.arange(0, m, stride), m - 1))
    out: list = [None] * m
    with single_thread_blas():
        found, reps = refined_central_batch(a0[anchors], a1[anchors], a2[anchors], ndof, harmonics,
                                            copy_tol=copy_tol, families=True)
        settled = [a for a, r in zip(anchors, reps) if r is not None]
        for a, mu in zip(anchors, found):
            out[a] = mu
        if not settled:
            return out
        reps_at = dict(zip(anchors.tolist(), reps))
        settled = np.asarray(settled)
        others = np.setdiff1d(np.arange(m), anchors)
        if others.size == 0:
            return out
        nearest = settled[np.argmin(np.abs(others[:, None] - settled[None, :]), axis=1)]
        owner = np.concatenate([np.full(len(reps_at[a][0]), j) for j, a in enumerate(nearest.tolist())])
        seed_mu = np.concatenate([reps_at[a][0] for a in nearest.tolist()])
        seed_v = np.concatenate([reps_at[a][1] for a in nearest.tolist()])
        want = [2 * ndof] * len(others)
        found, _ = _settle_seeds(a0[others], a1[others], a2[others], owner, seed_mu, seed_v, want, ndof,
                                 harmonics, copy_tol, "rayleigh")
    for k, mu in zip(others.tolist(), found):
        out[k] = mu
    return out


def _distinct_families(found, want: int, copy_tol: float):
    """``found`` as an array if it holds `want` exponents with distinct multipliers, else ``None``."""
    if len(found) != want:
        return None
    mult = [cmath.exp(2.0 * math.pi * x) for x in found]
    for i in range(len(mult)):
        for j in range(i):
            if abs(mult[i] - mult[j]) <= copy_tol * max(1.0, abs(mult[i])):
                return None  # a repeated multiplier: let the dense way decide
    return np.asarray(found, dtype=complex)


# ============================================================================ dispatch


def central_exponents(a0, a1, a2, ndof: int, harmonics: int, *, zero_tol=None, copy_tol: float = 1e-6,
                      method: str = "auto", neighbours: bool = False, counts: dict | None = None):
    """Central exponents ``mu = lam / w`` of a stack of points, shapes ``(m, N, N)``.

    `method`: ``"dense"`` (:func:`dense_central`) or ``"refined"`` (= ``"auto"``): with
    `neighbours` (the points are consecutive, close points of a branch; no trivial exponents
    to drop) :func:`neighbour_seeded_central` first (any stack is answered right, but points
    far apart cost it more: Hill's part of a three-row stability map, 49 speeds 250 rpm apart at
    N = 130, took 0.57 s against 0.38 s), then :func:`refined_central_batch` for the points not
    settled, again with the Newton update where that was not settled (the nearly merged real
    pairs of super-harmonic resonances), then (``N > REFINE_MIN_SIZE``) :func:`refined_central`
    with its larger seed window, then :func:`dense_central` (stacked) for the rest; the same
    exponents as the dense way. Returns a list of ``m`` arrays; `counts`, if given, receives how many points each
    stage settled (keys ``"neighbour"``, ``"rayleigh"``, ``"newton"``, ``"single"``, ``"dense"``).
    """
    if method not in ("auto", "dense", "refined"):
        raise ValueError(f"method must be 'auto', 'dense' or 'refined', got {method!r}")
    counts = {} if counts is None else counts
    if method == "dense":
        counts["dense"] = len(a0)
        return [_snapped(mu) for mu in dense_central(a0, a1, a2, ndof, harmonics, zero_tol=zero_tol, copy_tol=copy_tol)]
    m = len(a0)
    group = max(1, int(BATCH_BYTES // (16 * a0.shape[-1] ** 2)))  # keep the stacked pencils in cache
    out: list = [None] * m

    def settled(stage, before):
        counts[stage] = counts.get(stage, 0) + before - sum(mu is None for mu in out)

    if neighbours and zero_tol is None and m >= 2 * NEIGHBOUR_STRIDE:
        block = max(group, 4 * NEIGHBOUR_STRIDE)
        for lo in range(0, m, block):
            hi = min(m, lo + block)
            out[lo:hi] = neighbour_seeded_central(a0[lo:hi], a1[lo:hi], a2[lo:hi], ndof, harmonics,
                                                  copy_tol=copy_tol, stride=NEIGHBOUR_STRIDE)
        settled("neighbour", m)
    for update in ("rayleigh", "newton"):
        todo = [k for k in range(m) if out[k] is None]
        for lo in range(0, len(todo), group):
            part = todo[lo : lo + group]
            found = refined_central_batch(a0[part], a1[part], a2[part], ndof, harmonics, zero_tol=zero_tol,
                                          copy_tol=copy_tol, update=update)
            for k, mu in zip(part, found):
                out[k] = mu
        settled(update, len(todo))
    if a0.shape[-1] > REFINE_MIN_SIZE:  # worth a second, better-seeded try before the dense way
        todo = [k for k in range(m) if out[k] is None]
        for k in todo:
            out[k] = refined_central(a0[k], a1[k], a2[k], ndof, harmonics, zero_tol=zero_tol, copy_tol=copy_tol)
        settled("single", len(todo))
    rest = [k for k in range(m) if out[k] is None]
    if rest:
        for k, mu in zip(rest, dense_central(a0[rest], a1[rest], a2[rest], ndof, harmonics,
                                             zero_tol=zero_tol, copy_tol=copy_tol)):
            out[k] = mu
    counts["dense"] = counts.get("dense", 0) + len(rest)
    if len({len(mu) for mu in out}) == 1:  # one vectorised snap for the whole stack
        return list(_snapped(np.stack(out)))
    return [_snapped(mu) for mu in out]


def _snapped(mu):
    """The exponents counted as self-conjugate families (:func:`_is_self_conjugate`: a real
    multiplier) with ``Im mu`` set to its multiple of 1/2, so that their multipliers come out
    real: refined to ``STEP_TOL``, ``Im mu`` is off by ~1e-7, i.e. ``Im`` of the multiplier by
    ~1e-6 of its modulus, the threshold at which a multiplier counts as real."""
    mu = np.array(mu, dtype=complex)
    half = np.round(2.0 * mu.imag) / 2.0
    snap = np.abs(2.0 * mu.imag - 2.0 * half) <= SELF_CONJUGATE_TOL
    mu[snap] = mu[snap].real + 1j * half[snap]
    return mu


# ============================================================================ along a branch

#: The seeded correction of an exponent stops when the first-order estimate of its error,
#: ``|w^H P(mu) v| / |w^H P'(mu) v|`` (``w`` the left null vector of the factorised bordered
#: matrix), is below this relative to ``max(1, |mu|)``, and the estimated remaining error of the
#: unit eigenvector (last step times ``rho / (1 - rho)``, ``rho`` at least ``FOLLOW_MIN_RHO``)
#: below ``FOLLOW_VECTOR_TOL``.
FOLLOW_TOL = 1e-12
FOLLOW_VECTOR_TOL = 1e-8
FOLLOW_MIN_RHO = 0.05

#: A factorised bordered matrix is reused at the next point while the vector contraction of
#: its last correction was below this; otherwise the next point factorises its own.
FOLLOW_REUSE_RHO = 0.05

#: Most chord steps of one correction (a slower one is restarted once from a fresh factorisation).
FOLLOW_MAX_STEPS = 8

#: Problems of at most this many unknowns ``N`` are not followed point by point (see
#: :func:`hbgear.engine.floquet.hill_exponents_along`): on the Duffing curve (N = 15, 167
#: points) the follower took 0.37-0.86 ms a point, the batched unseeded way 0.10-0.23 ms.
FOLLOW_MIN_SIZE = REFINE_MIN_SIZE

_LAPACK: dict = {}


def _lapack_lu():
    """``(zgetrf, zgetrs)`` of LAPACK (scipy's wrappers, looked up once)."""
    if not _LAPACK:
        _LAPACK["f"], _LAPACK["s"] = scipy.linalg.lapack.get_lapack_funcs(("getrf", "getrs"), dtype=np.complex128)
    return _LAPACK["f"], _LAPACK["s"]


def _products(abc, vectors: np.ndarray) -> np.ndarray:
    """``a_k v_j`` for the stacked pencil ``abc`` ``(3, N, N)`` and vectors ``(N, P)``: shape
    ``(3, N, P)``, from one real matrix product (the vectors viewed as ``(N, 2P)`` reals), so the
    matrices are read once for all the vectors of a point."""
    n, count = vectors.shape
    real = np.ascontiguousarray(vectors).view(np.float64)
    return (abc.reshape(3 * n, n) @ real).view(np.complex128).reshape(3, n, count)


class _Pair:
    """One eigenpair followed from point to point: exponent `mu`, unit eigenvector `v`, those of
    the point before (`prev_mu`, `prev_v`: the linear predictor), and the factorised bordered
    matrix ``B = [[P(mu_r), P'(mu_r) v_r], [v_r^H, 0]]`` of a reference (`lu`, `piv`, in the
    pair's own buffer), its last row ``v_r^H`` (`row`) and left null vector ``w^H`` (`left`), with
    the vector contraction `rho` of the last correction."""

    __slots__ = ("mu", "v", "prev_mu", "prev_v", "buf", "lu", "piv", "row", "left", "rho")

    def __init__(self, mu: complex, v: np.ndarray):
        self.mu, self.v, self.prev_mu, self.prev_v = complex(mu), v, None, None
        self.buf = self.lu = self.piv = self.row = self.left = None
        self.rho = 1.0

    def predicted(self) -> tuple[complex, np.ndarray]:
        """``(mu, v)`` extrapolated linearly from the last two points (in the last one's phase)."""
        if self.prev_mu is None:
            return self.mu, self.v
        overlap = np.vdot(self.prev_v, self.v)
        prev_v = self.prev_v * (overlap / abs(overlap)) if overlap != 0 else self.prev_v
        return 2.0 * self.mu - self.prev_mu, 2.0 * self.v - prev_v

    def advance(self, mu: complex, v: np.ndarray, rho: float) -> None:
        """Move to the corrected pair ``(mu, v)`` (`v` of any scale), keeping the last one."""
        self.prev_mu, self.prev_v = self.mu, self.v
        self.mu, self.v, self.rho = complex(mu), v / np.linalg.norm(v), rho

    def conjugated(self) -> _Pair:
        """The conjugate eigenpair (real matrices), without a factorisation."""
        pair = _Pair(self.mu.conjugate(), self.v.conj())
        if self.prev_mu is not None:
            pair.prev_mu, pair.prev_v = self.prev_mu.conjugate(), self.prev_v.conj()
        return pair


def _factor(pair: _Pair, abc, mu: complex, v: np.ndarray, scratch: np.ndarray) -> bool:
    """Factorise the bordered matrix at ``(mu, v)`` (unit `v`) into the pair's buffer: the LU of
    its transpose, in place (the buffer is C-ordered, its transpose Fortran-ordered); then the
    left null vector ``w`` from ``B^H (w, beta) = e_last``. **Returns:** ``False`` if singular."""
    n = v.shape[0]
    if pair.buf is None or pair.buf.shape[0] != n + 1:
        pair.buf = np.empty((n + 1, n + 1), dtype=complex)
    b = pair.buf
    top = b[:n, :n]
    np.multiply(abc[1], mu, out=top)
    np.multiply(abc[2], mu * mu, out=scratch)
    top += scratch
    top += abc[0]
    p = _products(abc, v[:, None])[:, :, 0]
    b[:n, n] = p[1] + (2.0 * mu) * p[2]
    row = v.conj()
    b[n, :n] = row
    b[n, n] = 0.0
    getrf, getrs = _lapack_lu()
    lu, piv, info = getrf(b.T, overwrite_a=1)
    if info != 0:
        pair.lu = None
        return False
    last = np.zeros(n + 1, dtype=complex)
    last[n] = 1.0
    y, info = getrs(lu, piv, last, trans=0)  # B^T conj(u) = e: conj(u) = (w^H, conj(beta))
    if info != 0 or not np.all(np.isfinite(y)):
        pair.lu = None
        return False
    pair.lu, pair.piv, pair.row, pair.left = lu, piv, row, y[:n].copy()
    return True


class _Correction:
    """The state of one pair's correction at a point (:func:`_correct`)."""

    __slots__ = ("pair", "mu", "v", "last", "rho", "steps", "restarted")

    def __init__(self, pair: _Pair, mu: complex, v: np.ndarray):
        self.pair, self.mu, self.v = pair, mu, v / (pair.row @ v)
        self.last = self.rho = None
        self.steps, self.restarted = 0, False

    def converged(self, p) -> bool:
        """The convergence test of :func:`_correct` at the current iterate (products `p`)."""
        if self.rho is None or self.last * max(self.rho, FOLLOW_MIN_RHO) > FOLLOW_VECTOR_TOL * (1.0 - self.rho):
            return False
        mu, left = self.mu, self.pair.left
        slope = abs(left @ (p[1] + (2.0 * mu) * p[2]))
        return abs(left @ (p[0] + mu * p[1] + (mu * mu) * p[2])) <= FOLLOW_TOL * max(1.0, abs(mu)) * slope

    def step(self, p, abc, scratch) -> bool:
        """One chord step (restarted once from a fresh factorisation when slow); ``False`` on failure."""
        n, pair, mu = self.v.shape[0], self.pair, self.mu
        f = np.empty(n + 1, dtype=complex)
        f[:n] = p[0] + mu * p[1] + (mu * mu) * p[2]
        f[n] = pair.row @ self.v - 1.0
        dx, info = _lapack_lu()[1](pair.lu, pair.piv, f, trans=1)
        if info != 0 or not np.all(np.isfinite(dx)):
            return False
        self.v = self.v - dx[:n]
        self.mu = mu - dx[n]
        self.steps += 1
        step = float(np.linalg.norm(dx[:n])) / float(np.linalg.norm(self.v))
        self.rho = None if self.last is None else (0.0 if step == 0.0 else step / max(self.last, 1e-300))
        self.last = step
        if self.rho is not None and (self.rho >= 0.5 or self.steps >= FOLLOW_MAX_STEPS):
            if self.restarted:
                return False
            unit = self.v / np.linalg.norm(self.v)
            if not _factor(pair, abc, self.mu, unit, scratch):
                return False
            self.v, self.last, self.rho = unit / (pair.row @ unit), None, None
            self.steps, self.restarted = 0, True
        return True


def _correct(pairs, abc, scratch) -> bool:
    r"""Correct every pair of `pairs` onto an eigenpair of ``P(mu) = a0 + mu a1 + mu^2 a2``
    (``abc`` the stack of the three) from its linear predictor: chord steps on
    ``F(v, mu) = (P(mu) v, v_r^H v - 1) = 0`` with the factorised bordered matrix of the pair's
    reference, ``(dv, dmu) = -B^{-1} F`` (a regular matrix at a simple exponent); the pairs step
    together, so each step reads the matrices once (:func:`_products`). A pair's reference is its
    last one while that contracted by less than :data:`FOLLOW_REUSE_RHO`, else this point at the
    predicted pair; a correction that contracts by less than 1/2 per step, or takes more than
    :data:`FOLLOW_MAX_STEPS` steps, is restarted once from a factorisation at its iterate.
    Converged as :data:`FOLLOW_TOL` says (the exponent's error estimated to first order from the
    residual with the left null vector, which holds whatever the contraction; the vector's from
    its steps).

    **Returns:** whether all converged (the pairs updated then; left as they were otherwise).
    """
    work = []
    for pair in pairs:
        mu, v = pair.predicted()
        if (pair.lu is None or pair.rho > FOLLOW_REUSE_RHO) and not _factor(pair, abc, mu, v / np.linalg.norm(v),
                                                                             scratch):
            return False
        work.append(_Correction(pair, mu, v))
    active = list(work)
    while active:
        prods = _products(abc, np.stack([c.v for c in active], axis=1))
        still = []
        for j, c in enumerate(active):
            p = prods[:, :, j]
            if c.converged(p):
                continue
            if not c.step(p, abc, scratch):
                return False
            still.append(c)
        active = still
    for c in work:
        c.pair.advance(c.mu, c.v, c.rho)
    return True


class _Family:
    """A family of copies followed along a branch: its central member `rep` and, where the walk
    needs it (``|centre| > 1/4``), the neighbouring copy `copy` at ``rep.mu + i k``."""

    __slots__ = ("rep", "copy", "k")

    def __init__(self, rep: _Pair):
        self.rep, self.copy, self.k = rep, None, 0


_CENTRE_WEIGHTS: dict = {}


def _centre(v: np.ndarray, ndof: int, harmonics: int) -> float:
    """:func:`harmonic_centre` of one vector: ``sum_k k (|a_k - i b_k|^2 - |a_k + i b_k|^2) / 4`` is
    ``-sum_k k Im(a_k conj(b_k))``, over ``|a_0|^2 + sum_k (|a_k|^2 + |b_k|^2) / 2``."""
    key = (ndof, harmonics)
    if key not in _CENTRE_WEIGHTS:
        block = 2 * harmonics + 1
        base = np.arange(ndof)[:, None] * block
        k = np.arange(1, harmonics + 1)
        _CENTRE_WEIGHTS[key] = ((base + 2 * k - 1).ravel(), (base + 2 * k).ravel(), np.tile(k, ndof).astype(float),
                                (base[:, 0]).ravel())
    ia, ib, k, i0 = _CENTRE_WEIGHTS[key]
    a, b = v[ia], v[ib]
    total = float(np.sum(np.abs(v[i0]) ** 2)) + 0.5 * float(np.sum(a.real**2 + a.imag**2 + b.real**2 + b.imag**2))
    return -float(k @ (a * b.conj()).imag) / max(total, 1e-300)


def _settle(family: _Family, abc, ndof: int, harmonics: int, scratch) -> bool:
    """One step of :func:`_most_central_member`'s walk for a followed family whose members have
    been corrected at this point: ``rep`` stays if ``|centre| <= 1/4``; else the copy towards the
    centre (``k = sign(centre)``: the conjugate for a real multiplier's family, else the followed
    copy, or a new one corrected from the shifted eigenvector) replaces it if it is more central,
    and the walk must then stop there. **Returns:** whether the family settled on its most
    central member (``False``: the point is left to the unseeded way)."""
    rep = family.rep
    c = _centre(rep.v, ndof, harmonics)
    if abs(c) <= 0.25:
        family.copy, family.k = None, 0
        return True
    k = 1 if c > 0 else -1
    if _is_conjugate_copy(rep.mu, k):
        if rep.mu.imag < 0.0:  # the tie between conjugate copies goes to Im mu >= 0
            family.rep = rep.conjugated()
        family.copy, family.k = None, 0
        return True
    if family.copy is None or family.k != k:
        copy = _Pair(rep.mu + 1j * k, _shift_harmonics(rep.v, ndof, harmonics, k))
        if not _correct([copy], abc, scratch):
            return False
        family.copy, family.k = copy, k
    copy = family.copy
    if abs(copy.mu - (rep.mu + 1j * k)) > 0.25:
        return False
    c_copy = _centre(copy.v, ndof, harmonics)
    if centrality(copy.mu, c_copy) >= centrality(rep.mu, c):
        return True
    family.rep, family.copy, family.k = copy, rep, -k  # the walk moves on ...
    return abs(c_copy) <= 0.25 or (c_copy < 0) == (k > 0)  # ... and must stop there


class CentralFollower:
    """Central Floquet exponents point after point along a branch, each point seeded from the one before.

    Call it with the Hill matrices of consecutive points of a branch, stacked ``(3, N, N)``
    (``a0, a1, a2``); it returns the exponents ``mu`` as :func:`central_exponents` does (the same
    exponents, snapped). At each point every followed eigenpair is corrected from the previous
    point's (:func:`_correct`: chord steps with a factorised bordered matrix, reused from point to
    point while it contracts fast), each family walked one copy where :func:`_most_central_member`
    would walk (:func:`_settle`), and the point accepted on the terms of
    :func:`refined_central_batch`: every correction converged, every family on its most central
    member, ``2n`` families (less the trivial ones) with distinct multipliers (to `copy_tol`) and
    no exponent within `zero_tol` of 0. Otherwise (the first point, a split or merger of real
    multipliers, a walk of more than one copy, a correction that fails) the point goes to
    :func:`central_exponents` and the families restart from its result. :meth:`reset` breaks the
    chain (the next point is not a neighbour of the last). `predict`: each pair starts from its
    value at the last point extrapolated linearly with the one before (points evenly spaced along
    the branch), else from the last value (e.g. the iterates of a root finder).

    **Attributes:** `seeded`, `unseeded`: points settled each way so far.
    """

    def __init__(self, ndof: int, harmonics: int, *, zero_tol=None, copy_tol: float = 1e-6, predict: bool = True):
        self.ndof, self.harmonics, self.zero_tol, self.copy_tol = ndof, harmonics, zero_tol, copy_tol
        self.predict = predict
        self.families: list[_Family] | None = None
        self.want = 0
        self.seeded = self.unseeded = 0
        self._scratch = None

    def reset(self) -> None:
        """Forget the followed families: the next point starts unseeded."""
        self.families = None

    def __call__(self, abc) -> np.ndarray:
        abc = np.asarray(abc, dtype=float)
        if self._scratch is None or self._scratch.shape != abc.shape[1:]:
            self._scratch = np.empty(abc.shape[1:], dtype=complex)
        with single_thread_blas():
            mu = self._seeded(abc) if self.families is not None else None
            if mu is not None:
                self.seeded += 1
                return mu
            self.unseeded += 1
            mu = central_exponents(abc[None, 0], abc[None, 1], abc[None, 2], self.ndof, self.harmonics,
                                   zero_tol=self.zero_tol, copy_tol=self.copy_tol)[0]
            self._restart(abc, mu)
        return mu

    def _seeded(self, abc):
        """The exponents from the followed families, or ``None`` (the families are then dropped)."""
        found = self._follow(abc)
        out = None if found is None else _distinct_families(found, self.want, self.copy_tol)
        if out is None:
            self.families = None
            return None
        return _snapped(out)

    def _follow(self, abc):
        """Every family corrected and settled: the exponents (a conjugate added where the family
        is not its own), or ``None``."""
        scratch = self._scratch
        members = [p for fam in self.families for p in ((fam.rep,) if fam.copy is None else (fam.rep, fam.copy))]
        if not self.predict:
            for pair in members:
                pair.prev_mu = pair.prev_v = None
        if not _correct(members, abc, scratch):
            return None
        found: list[complex] = []
        for fam in self.families:
            if not _settle(fam, abc, self.ndof, self.harmonics, scratch):
                return None
            mu = fam.rep.mu
            if self.zero_tol is not None and abs(mu) < self.zero_tol:
                return None
            if any(abs(mu - f) <= 1e-9 * max(1.0, abs(f)) for f in found):
                return None
            found.append(mu)
            if not _is_self_conjugate(mu):
                found.append(mu.conjugate())
        return found

    def _restart(self, abc, mu) -> None:
        """Families from exponents found the unseeded way: one per exponent up to conjugation,
        its eigenvector from two inverse-iteration steps at the (converged) exponent."""
        self.want = len(mu)
        families = []
        n = abc.shape[-1]
        start = np.array([1.0, 1j]) @ np.random.default_rng(0).standard_normal((2, n))
        for x in (complex(y) for y in mu):
            if x.imag < 0.0 and not _is_self_conjugate(x) and any(abs(x.conjugate() - y) <= 1e-9 * max(1.0, abs(y))
                                                                  for y in mu):
                continue  # followed as the conjugate of its partner
            try:
                lu = scipy.linalg.lu_factor(abc[0] + x * abc[1] + (x * x) * abc[2], check_finite=False)
                v = scipy.linalg.lu_solve(lu, start, check_finite=False)
                v = scipy.linalg.lu_solve(lu, v / np.linalg.norm(v), check_finite=False)
            except (ValueError, np.linalg.LinAlgError):
                return
            norm = np.linalg.norm(v)
            if not np.isfinite(norm) or norm == 0.0:
                return
            families.append(_Family(_Pair(x, v / norm)))
        self.families = families
