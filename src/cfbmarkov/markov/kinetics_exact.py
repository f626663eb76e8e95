"""Exact answers of linear kinetics along the chain's paths (no sampling noise).

``docs/definitions.md`` (Properties along particle paths) derives them. A residence is a
first passage through an absorbing chain: Q among the transient states, r the probability
of leaving on the next lag, e where particles enter. Over a lag in state s the property
maps exactly as v' = a_s v + b_s (:mod:`cfbmarkov.kinetics.laws`), so the value at the
exit is v_exit = A v0 + B with A = prod a along the path and B an affine sum. With
D = diag(a), conditioning on the exit (p = e (I - Q)^-1 r, 1 but for trapped mass):

    E[A]    = e alpha / p,   alpha = (I - D Q)^-1 D r
    E[B]    = e beta / p,    beta  = (I - Q)^-1 (b o (r + Q alpha))
    E[A^2]  = e gamma / p,   gamma = (I - D^2 Q)^-1 D^2 r
    E[2AB]  = e delta / p,   delta = (I - D Q)^-1 (2 a o b o (r + Q gamma))
    E[B^2]  = e eps / p,     eps   = (I - Q)^-1 (b^2 o (r + Q gamma) + b o (Q delta))

(o the element-wise product); E[v_exit] = E[A] v0 + E[B] and E[v_exit^2] =
E[A^2] v0^2 + E[2AB] v0 + E[B^2].

Carried properties: a value carried across passes enters the next residence where the
last one landed, and where that is depends on where the last one entered (a pass up
keeps its column), so the passes are not independent. The same recursions with the exits
split by landing state, R [n, M] instead of r, give from each entry state j the moments
landing in each j' (conditioned on leaving; M x M: A_jj' = E[A 1{j'}] and so on), and the
value's mass entering each entry state in the steady state solves u = A^T u + B^T nu (nu
the stationary entry distribution), its second moment's s = (A^2)^T s + (2AB)^T u +
(B^2)^T nu; the steady mean is sum u. The bed's steady state per state:
occupancy nu = e (I - Q)^-1 and value mass mu = (v0 e + (nu o b) Q) (I - D Q)^-1, the mean
mu / nu (the value at the frames, each lag's start; for a carried property u at the entry
states in place of v0 e).

An open riser's chain is Q = diag(1 - r) P with the model's exit probabilities and entry
distribution; a periodic riser's is the chain on (lap-deficit level, state) of
:mod:`cfbmarkov.markov.first_passage` (the pass up through the top from level 0 ends a
residence), entered at level 0 with the exact RTD's entry distribution. States from which
no exit can be reached hold trapped mass and are left out, as the exact RTD leaves them.

References
----------
J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton (1960), Ch. III
(absorbing chains, the fundamental matrix). H. Berthiaux, V. Mizonov and V. Zhukov,
"Application of the theory of Markov chains to model different processes in particle
technology", Powder Technology 157, 128-137 (2005). A. T. Harris, J. F. Davidson and
R. B. Thorpe, Chemical Engineering Science (2003), on the particle residence-time
distribution of CFB risers. O. Levenspiel, Chemical Reaction Engineering, 3rd ed., Wiley
(1999), Ch. 15-16 (the segregated-flow model, for contrast).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from cfbmarkov._repr import compact_repr
from cfbmarkov.errors import InputError
from cfbmarkov.kinetics import Kinetics, StateKinetics
from cfbmarkov.kinetics.spec import on_states
from cfbmarkov.markov.connectivity import closed_classes, states_reaching
from cfbmarkov.markov.first_passage import (_live_levels, deficit_matrix, rtd_of_split_chain,
                                            split_by_pass)


@dataclass(frozen=True)
class ExitMoments:
    """Moments of the exit value v_exit = A v0 + B of one residence, and the bed's value
    mass, for one linear law on one absorbing chain (module docstring).

    Attributes
    ----------
    mean_a, mean_b, mean_a2, mean_2ab, mean_b2 : float
        E[A], E[B], E[A^2], E[2AB], E[B^2], conditional on leaving.
    occupancy : ndarray of float64, shape (n,)
        nu = e (I - Q)^-1 per transient state (expected lags spent there per entry).
    mass_per_start, mass_rest : ndarray of float64, shape (n,)
        mu = v0 * mass_per_start + mass_rest, the expected sum of the value over the lags
        spent in each state per entry.
    exit_probability : float
        p, the probability that an entering particle leaves (1 but for trapped mass).
    mean_1ma, mean_1ma2 : float
        E[1 - A] and E[1 - A^2], computed from 1 - a (not as 1 - E[A], which loses every
        digit where rates are small): e (I - D Q)^-1 ((1 - a) o x) / p with x = (I - Q)^-1 r,
        and likewise with D^2, since (I - D Q)(x - alpha) = (1 - a) o x.
    """

    mean_a: float
    mean_b: float
    mean_a2: float
    mean_2ab: float
    mean_b2: float
    occupancy: np.ndarray
    mass_per_start: np.ndarray
    mass_rest: np.ndarray
    exit_probability: float
    mean_1ma: float = float("nan")
    mean_1ma2: float = float("nan")

    def exit_mean(self, v0: float) -> float:
        """E[v_exit] for the entry value ``v0``."""
        return self.mean_a * v0 + self.mean_b

    def exit_second(self, v0: float) -> float:
        """E[v_exit^2] for the entry value ``v0``."""
        return self.mean_a2 * v0 * v0 + self.mean_2ab * v0 + self.mean_b2


#: SuperLU's column ordering for the residence chain's systems: their states' own order
#: (level by level, cells row by row within a level: a block-tridiagonal, banded matrix)
#: keeps the fill near the band, and ordering it anew costs more than the fill it saves
#: (``exact_kinetics`` of one first-order property, median of 5, 2026-12-06: 3 m/s
#: paper-scale models on 6 x 38 cells, 10 and 32 lap deficits, 0.047 -> 0.025 s and
#: 0.135 -> 0.072 s; the tutorial's synthetic model 0.092 -> 0.029 s; a 1824-state velocity
#: memory on 64 deficits 5.4 -> 3.3 s; a 1596-state previous-cell memory 0.43 -> 0.47 s),
#: as for the exact RTD's moments (:func:`~cfbmarkov.markov.first_passage.rtd_moments`)
ORDERING = "NATURAL"


def _lu(matrix):
    """SuperLU factors of a residence chain's system in :data:`ORDERING`."""
    return splu(sp.csc_matrix(matrix), permc_spec=ORDERING)


def _factors(q, a, c=None, lu_q=None) -> tuple:
    """Q as CSC, a, 1 - a (``c``, else formed), and the LU factors of I - Q (``lu_q`` where
    given), I - D Q and I - D^2 Q that the exit moments solve with."""
    q = sp.csc_matrix(q, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    c = 1.0 - a if c is None else np.asarray(c, dtype=np.float64)
    eye = sp.identity(q.shape[0], format="csc")
    if lu_q is None:
        lu_q = _lu(eye - q)
    return (q, a, c, lu_q, _lu(eye - sp.diags(a) @ q), _lu(eye - sp.diags(a * a) @ q))


def exit_moments(q, r, e, a, b, lu_q=None, c=None, factors=None) -> ExitMoments:
    """:class:`ExitMoments` of an absorbing chain (module docstring).

    Parameters
    ----------
    q : ndarray or scipy.sparse matrix of float64, shape (n, n)
        Q, sub-stochastic, among transient states from each of which an exit can be
        reached (I - Q invertible).
    r : ndarray of float64, shape (n,)
        Probability of leaving on the next lag.
    e : ndarray of float64, shape (n,)
        Entry distribution (sums to 1).
    a, b : ndarray of float64, shape (n,)
        The affine map of one lag per state, v' = a v + b.
    lu_q : scipy.sparse.linalg.SuperLU, optional
        The LU factors of I - Q (``splu``), shared by the properties of one chain.
    c : ndarray of float64, shape (n,), optional
        1 - a computed without cancellation (``-expm1(-k lag)``); default 1 - a.
    factors : tuple, optional
        What :func:`_factors` returns for these q, a, c (the LU factors of I - D Q and
        I - D^2 Q), where already formed: another b on the same chain and law.

    Returns
    -------
    ExitMoments

    Raises
    ------
    InputError
        If no entering particle can leave.
    """
    r, e, b = (np.asarray(x, dtype=np.float64) for x in (r, e, b))
    q, a, c, lu_q, lu_dq, lu_d2q = factors if factors is not None else _factors(q, a, c, lu_q)
    leaves = lu_q.solve(r)
    p = float(e @ leaves)
    if not p > 0:
        raise InputError("no particle that enters can leave in the model: every residence is "
                         "trapped")
    alpha = lu_dq.solve(a * r)
    beta = lu_q.solve(b * (r + q @ alpha))
    gamma = lu_d2q.solve(a * a * r)
    w = r + q @ gamma
    delta = lu_dq.solve(2.0 * a * b * w)
    eps = lu_q.solve(b * b * w + b * (q @ delta))
    occupancy = lu_q.solve(e, trans="T")
    per_start = lu_dq.solve(e, trans="T")
    rest = lu_dq.solve(q.T @ (occupancy * b), trans="T")
    forget = float(e @ lu_dq.solve(c * leaves)) / p
    forget2 = float(e @ lu_d2q.solve(c * (2.0 - c) * leaves)) / p
    return ExitMoments(float(e @ alpha) / p, float(e @ beta) / p, float(e @ gamma) / p,
                       float(e @ delta) / p, float(e @ eps) / p, occupancy, per_start, rest, p,
                       forget, forget2)


@dataclass(frozen=True)
class CarriedMoments:
    """A carried property's exit moments resolved by entry state: the value a particle
    brings back depends on where its previous residence landed, and where it lands next
    depends on where it entered (a pass up keeps its column), so the passes are not
    independent of each other (module docstring, Carried properties).

    The entry states are those particles keep circulating through: an entry state from
    which no exit can be reached (a trap) is left out. Where every residence ends in a kept
    one (the rows of L sum to 1 within :data:`SURVIVAL_TOL`), every moment is conditioned on
    that; where some end in a trap, or fall deeper than the lap deficits followed, the
    moments are not conditioned and the particles still circulating are followed
    (``survivors``), their survival counted per pass (the particles that land in a trap
    never come back, so they carry no value into the steady state of those that do).

    Attributes
    ----------
    kept : ndarray of int64, shape (M,)
        The entry states kept, as indices into the residence chain's entry states.
    entry : ndarray of float64, shape (M,)
        nu, the stationary distribution of the kept entry states (the exact RTD's).
    a, b, a2, ab2, b2, forget, forget2 : ndarray of float64, shape (M, M)
        From entry state j, landing in j' (conditioned on landing in a kept one unless
        ``survivors``): E[A 1{j'}], E[B 1{j'}],
        E[A^2 1{j'}], E[2AB 1{j'}], E[B^2 1{j'}], E[(1 - A) 1{j'}] and E[(1 - A^2) 1{j'}],
        the last two formed without cancellation.
    landing : ndarray of float64, shape (M, M)
        L, from entry state j the probability of landing in j' (rows sum to 1 unless
        ``survivors``).
    mean_by_entry, second_by_entry : ndarray of float64, shape (M,)
        u and s, the steady value's mass and second moment's mass by entry state
        (sum u the steady mean).
    survivors : ndarray of float64, shape (M,), optional
        Where some residences end in a trap or fall deeper than the lap deficits followed
        (L's rows sum to less than 1 by more than :data:`SURVIVAL_TOL`): the moments and L
        are not conditioned on landing, and this is phi, the entry distribution of the
        particles still circulating after many passes, first entered with ``entry``; u
        and s are theirs. None where every residence lands in a kept entry state (the
        moments conditioned on it).
    """

    kept: np.ndarray
    entry: np.ndarray
    a: np.ndarray
    b: np.ndarray
    a2: np.ndarray
    ab2: np.ndarray
    b2: np.ndarray
    forget: np.ndarray
    forget2: np.ndarray
    landing: np.ndarray
    mean_by_entry: np.ndarray = field(default=None, repr=False)
    second_by_entry: np.ndarray = field(default=None, repr=False)
    discounted: object = field(default=None, repr=False, compare=False)   # LU of I - D Q
    survivors: np.ndarray | None = field(default=None, repr=False)

    def entering_mass(self, entering: np.ndarray) -> np.ndarray:
        """The value's mass per transient state, summed over the lags spent there, of the
        values ``entering`` per transient state (u at the entry states; mu's first term,
        module docstring): entering (I - D Q)^-1."""
        return self.discounted.solve(np.asarray(entering, dtype=np.float64), trans="T")

    def shifted(self, c: float) -> "CarriedMoments":
        """The same moments for w = v - ``c``: a residence's w_exit = A w_entry + B', B' =
        B - (1 - A) c, so E[B'] = b - c forget, E[2AB'] = ab2 + 2c (forget - forget2)
        (A - A^2 = (1 - A^2) - (1 - A)) and E[B'^2] = b2 - 2c (b - ab2 / 2) + c^2 (2 forget
        - forget2) ((1 - A)^2 = 2 (1 - A) - (1 - A^2)), every term free of the cancellation
        that E[v^2] - E[v]^2 suffers where the values lie far from 0 against their spread
        (an activity of 0.999999 after a pass at a slow rate, its SD 3e-7). For
        :meth:`after_passes`; the steady masses are left out.

        Parameters
        ----------
        c : float
            The shift (a value near the moments' mean).

        Returns
        -------
        CarriedMoments
        """
        c = float(c)
        return CarriedMoments(
            self.kept, self.entry, self.a, self.b - c * self.forget, self.a2,
            self.ab2 + 2.0 * c * (self.forget - self.forget2),
            self.b2 - 2.0 * c * (self.b - 0.5 * self.ab2)
            + c * c * (2.0 * self.forget - self.forget2),
            self.forget, self.forget2, self.landing, survivors=self.survivors)

    def carried(self) -> tuple[float, float]:
        """The steady mean and second moment of a value carried across residences.

        Returns
        -------
        mean, second : float

        Raises
        ------
        InputError
            If no relaxation acts wherever particles go (no steady state).
        """
        return float(self.mean_by_entry.sum()), float(self.second_by_entry.sum())

    def after_passes(self, v0: float, passes: int) -> tuple[float, float]:
        """Mean and second moment of the exit value after ``passes`` residences of a value
        carried from ``v0``, the first entered with the stationary entry distribution:
        u_k = A^T u_(k-1) + B^T nu, s_k = (A^2)^T s_(k-1) + (2AB)^T u_(k-1) + (B^2)^T nu
        from u_0 = v0 nu, s_0 = v0^2 nu; the mean sum u_k, the second moment sum s_k. The
        recursion is linear in (u, s, 1): its matrix raised to the power ``passes`` by
        repeated squaring (2 log2(passes) products of (2M + 1)-square matrices, not one
        step a pass). With ``survivors`` the surviving mass w is followed as well
        (:func:`_pass_step`: u_k = A^T u_(k-1) + B^T w_(k-1), w_k = L^T w_(k-1) from
        w_0 = nu), the mean and second moment those of the particles that complete the
        passes, sum u_k / sum w_k and sum s_k / sum w_k, each squaring rescaled.

        Parameters
        ----------
        v0 : float
            The value at the first entry.
        passes : int
            Residences, at least 1.

        Returns
        -------
        mean, second : float
        """
        m = self.entry.size
        if self.survivors is not None:
            # the surviving mass w_k = L^T w_(k-1) too (:func:`_pass_step`); the mean among
            # the particles that complete the passes
            power = _pass_step(self.a, self.b, self.a2, self.ab2, self.b2, self.landing)
            state = np.concatenate([float(v0) * self.entry, float(v0) ** 2 * self.entry,
                                    self.entry])
            left = int(passes)
            while left:     # step^passes by squaring, each product rescaled: the surviving
                if left & 1:        # mass falls as rho^N and would underflow, the ratios not
                    state = power @ state
                    state /= max(float(np.max(np.abs(state))), np.finfo(np.float64).tiny)
                left >>= 1
                if left:
                    power = power @ power
                    power /= max(float(np.max(np.abs(power))), np.finfo(np.float64).tiny)
            mass = float(state[2 * m:].sum())
            if not mass > 0.0:
                raise InputError(f"after {passes} passes no particle is left circulating "
                                 "(every one has landed in a trap)")
            return float(state[:m].sum()) / mass, float(state[m:2 * m].sum()) / mass
        step = np.zeros((2 * m + 1, 2 * m + 1))
        step[:m, :m] = self.a.T
        step[:m, 2 * m] = self.b.T @ self.entry
        step[m:2 * m, :m] = self.ab2.T
        step[m:2 * m, m:2 * m] = self.a2.T
        step[m:2 * m, 2 * m] = self.b2.T @ self.entry
        step[2 * m, 2 * m] = 1.0
        state = np.concatenate([float(v0) * self.entry, float(v0) ** 2 * self.entry, [1.0]])
        state = np.linalg.matrix_power(step, int(passes)) @ state
        tiny = np.finfo(np.float64).tiny       # below the normal floats: round-off of 0
        mean, second = float(state[:m].sum()), float(state[m:2 * m].sum())
        return (0.0 if abs(mean) < tiny else mean), (0.0 if abs(second) < tiny else second)


def _steady_by_entry(forget: np.ndarray, landing: np.ndarray, rhs: np.ndarray,
                     entry: np.ndarray) -> np.ndarray:
    """Solve u = (L - F)^T u + rhs for u, F = ``forget`` small where rates are (the
    equations' sum, f . u = sum rhs with f the row sums of F, replaces the one at nu's
    largest entry: I - L^T is singular, so the system's own rows lose every digit of f
    that round-off in L leaves)."""
    m = landing.shape[0]
    system = np.eye(m) - landing.T + forget.T
    rhs = np.array(rhs, dtype=np.float64)
    k = int(np.argmax(entry))
    system[k] = forget.sum(axis=1)
    rhs[k] = rhs.sum()
    return np.linalg.solve(system, rhs)


def carried_moments(q, r, e, a, b, landing, entry_rows, lu_q=None, c=None,
                    factors=None) -> CarriedMoments:
    """:class:`CarriedMoments` of a periodic riser's residence chain (module docstring,
    Carried properties): the landing-resolved moments, by the recursions of
    :func:`exit_moments` with the exits R split by landing state instead of r.

    Parameters
    ----------
    q, r, e, a, b, lu_q, c, factors
        As :func:`exit_moments`.
    landing : scipy.sparse matrix of float64, shape (n, M)
        R, the exits split by the entry state they land in (:func:`residence_chain`).
    entry_rows : ndarray of int64, shape (M,)
        Each entry state's transient state (-1: not live).

    Returns
    -------
    CarriedMoments

    Raises
    ------
    InputError
        If no relaxation acts wherever particles go: the value keeps its start, and there is
        no steady state.
    """
    b = np.asarray(b, dtype=np.float64)
    q, a, c, lu_q, lu_dq, lu_d2q = factors if factors is not None else _factors(q, a, c, lu_q)
    big_r = np.asarray(sp.csr_matrix(landing).toarray(), dtype=np.float64)
    lands = lu_q.solve(big_r)                                   # (I - Q)^-1 R
    alpha = lu_dq.solve(a[:, None] * big_r)
    beta = lu_q.solve(b[:, None] * (big_r + q @ alpha))
    gamma = lu_d2q.solve((a * a)[:, None] * big_r)
    w = big_r + q @ gamma
    delta = lu_dq.solve((2.0 * a * b)[:, None] * w)
    eps = lu_q.solve((b * b)[:, None] * w + b[:, None] * (q @ delta))
    forget = lu_dq.solve(c[:, None] * lands)                    # (I - D Q)^-1 ((1-a) o L)
    forget2 = lu_d2q.solve((c * (2.0 - c))[:, None] * lands)  # 1 - a^2 = c (2 - c)
    kept = np.flatnonzero(entry_rows >= 0)
    while kept.size:        # entries whose residences can land in a kept one
        stays = lands[entry_rows[kept]][:, kept].sum(axis=1) > 0
        if stays.all():
            break
        kept = kept[stays]
    if not kept.size:
        raise InputError("no particle that enters comes back to an entry from which the top "
                         "can be reached: a carried property has no steady state")
    rows = entry_rows[kept]
    leave = lands[rows][:, kept].sum(axis=1)           # ends, landing in a kept entry
    nu = np.asarray(e, dtype=np.float64)[rows]
    nu = nu / nu.sum()
    raw = [x[rows][:, kept] for x in (alpha, beta, gamma, delta, eps, forget, forget2, lands)]
    if np.max(np.abs(leave - 1.0)) > SURVIVAL_TOL:
        return _survivors(kept, nu, *raw, lu_dq)
    scale = (1.0 / leave)[:, None]
    ma, mb, ma2, mab2, mb2, mf, mf2, land = (x * scale for x in raw)
    _check_relaxation(mf, land)
    u = _steady_by_entry(mf, land, mb.T @ nu, nu)
    second = _steady_by_entry(mf2, land, mab2.T @ u + mb2.T @ nu, nu)
    return CarriedMoments(kept, nu, ma, mb, ma2, mab2, mb2, mf, mf2, land, u, second, lu_dq)


def _check_relaxation(forget: np.ndarray, landing: np.ndarray) -> None:
    for members in closed_classes(sp.csr_matrix(landing)):
        if not forget[members].sum() > 0.0:
            raise InputError("a carried property with a zero rate wherever the particles of "
                             "some entry states go (they land back among themselves) has no "
                             "steady state there (it keeps its start value): use start = "
                             "entry")


def _pass_step(a, b, a2, ab2, b2, landing) -> np.ndarray:
    """The linear map of one pass on (u, s, w), the value's and its square's mass by entry
    state and the mass still circulating: u' = A^T u + B^T w, s' = (A^2)^T s + (2AB)^T u +
    (B^2)^T w, w' = L^T w (moments not conditioned on landing)."""
    m = landing.shape[0]
    step = np.zeros((3 * m, 3 * m))
    step[:m, :m] = a.T
    step[:m, 2 * m:] = b.T
    step[m:2 * m, :m] = ab2.T
    step[m:2 * m, m:2 * m] = a2.T
    step[m:2 * m, 2 * m:] = b2.T
    step[2 * m:, 2 * m:] = landing.T
    return step


def _survivors(kept, nu, ma, mb, ma2, mab2, mb2, mf, mf2, land, lu_dq) -> "CarriedMoments":
    """:class:`CarriedMoments` where some residences end in a trap or fall deeper than the
    lap deficits followed (the landing matrix's rows sum to less than 1 by more than
    :data:`SURVIVAL_TOL`): the moments are kept unconditioned, and the steady state is that
    of the particles still circulating after many passes, first entered with ``nu``: the
    limit of (u_N, s_N) / sum w_N under :func:`_pass_step`, taken by squaring the step
    (2^k passes after k squarings, each normalised) until it no longer changes (at most
    2^64 passes; a relaxation leaves its start value behind long before, and none at all
    is refused). Where no residence ends in a trap this is the fixed point that
    :func:`_steady_by_entry` solves for."""
    _check_relaxation(mf, land)
    m = nu.size
    step = _pass_step(ma, mb, ma2, mab2, mb2, land)
    start = np.concatenate([0.0 * nu, 0.0 * nu, nu])    # the steady state forgets v0
    power, state = step, None
    for _ in range(64):
        now = power @ start
        mass = now[2 * m:].sum()
        if not mass > 0.0:
            raise InputError("no particle keeps circulating: every residence ends, sooner or "
                             "later, in a trap; a carried property has no steady state")
        now = now / mass
        if state is not None and np.max(np.abs(now - state)) <= 1e-15 * np.max(np.abs(now)):
            state = now
            break
        state = now
        power = power @ power
        power /= np.max(np.abs(power))
    u, second, phi = state[:m], state[m:2 * m], state[2 * m:]
    return CarriedMoments(kept, nu, ma, mb, ma2, mab2, mb2, mf, mf2, land, u, second, lu_dq,
                          survivors=phi)


@dataclass(frozen=True)
class PropertyAnswer:
    """The exact answers for one property of a model. Every value is in the property's own
    unit, as its kinetics gives it (a conversion or an activity: a fraction, 0-1; a
    temperature: the unit of its ``temperature`` and ``initial``, K or degrees C alike).

    Attributes
    ----------
    name : str
        The property.
    start : str
        Its start rule.
    entry_value : float
        The value particles enter with (``initial``; for a carried property the steady
        mean of the values they come back with).
    exit_mean, exit_sd : float
        Mean and standard deviation of the value at the exit, per residence (the SD is
        sqrt(E[v^2] - E[v]^2), 0 where that lies within :data:`ROUND_OFF` of E[v^2];
        formed from the moments of v - E[v] where E[v^2] exceeds the variance by more
        than :data:`CENTRE_ABOVE`, then 0 within :data:`CENTRED_ROUND_OFF` of |E[v]|).
    bed_mean : float
        The bed's steady-state mean over all particles (per particle, at the frames).
    bed_mean_by_state : ndarray of float64, shape (S,)
        The steady-state mean per state (NaN where no particle stays).
    bed_mean_by_cell : ndarray of float64, shape (C,)
        The steady-state mean per cell of the grid (NaN where no particle stays).
    initial : float
        The value at the first entry (the kinetics file's ``initial``).
    moments : ExitMoments, optional
        The residence's exit moments, for :meth:`after_passes`.
    centred : CarriedMoments, optional
        A carried property's moments of v - ``centre`` (``centre`` its steady exit mean),
        formed where the values lie so far from zero against their spread that the moments
        of v lose their SD (:data:`CENTRE_ABOVE`); :meth:`after_passes` uses them.
    centre : float, optional
        The shift of ``centred`` (0 without it).
    """

    __repr__ = compact_repr

    name: str
    start: str
    entry_value: float
    exit_mean: float
    exit_sd: float
    bed_mean: float
    bed_mean_by_state: np.ndarray
    bed_mean_by_cell: np.ndarray
    initial: float = float("nan")
    moments: ExitMoments | None = field(default=None, repr=False, compare=False)
    centred: "CarriedMoments | None" = field(default=None, repr=False, compare=False)
    centre: float = 0.0

    def after_passes(self, passes: int) -> tuple[float, float]:
        """Mean and SD of the exit value after ``passes`` residences of a value carried
        from :attr:`initial` (:meth:`ExitMoments.after_passes`): the activity left after
        N passes through the riser, where the steady state of a carried deactivation is 0.

        Parameters
        ----------
        passes : int
            At least 1.

        Returns
        -------
        mean, sd : float

        Raises
        ------
        InputError
            If ``passes`` is below 1, or the answer holds no exit moments.
        """
        if not isinstance(self.moments, CarriedMoments):
            raise InputError(f"property {self.name}: passes are followed for a carried "
                             "property (start = \"carried\") only")
        if int(passes) != passes or passes < 1:
            raise InputError(f"passes {passes}: give a whole number of residences, at least 1")
        mean, second = self.moments.after_passes(self.initial, int(passes))
        # the spread from the moments of w = v - mean: E[v^2] - E[v]^2 keeps few digits
        # where the values lie far from 0 against their spread (an activity of 0.999999
        # after a pass at a slow rate; a temperature far from its steady state)
        # taken from the law centred on the steady state where there is one (its per-lag
        # maps shifted before they are summed keep the digits of values far from 0)
        base, centre = ((self.centred, self.centre) if self.centred is not None
                        else (self.moments, 0.0))
        mw, sw = base.shifted(mean - centre).after_passes(self.initial - mean, int(passes))
        variance, floor = sw - mw * mw, (CENTRED_ROUND_OFF * mean) ** 2
        return mean, float(np.sqrt(variance)) if variance > floor else 0.0

    def to_dict(self, passes=()) -> dict:
        """JSON-serialisable (the per-cell means as a list, null where NaN; with
        ``passes``, the mean and SD after each number of passes, :meth:`after_passes`)."""
        after = {str(n): dict(zip(("mean", "sd"), self.after_passes(n))) for n in passes}
        return {"start": self.start, "entry_value": self.entry_value, "initial": self.initial,
                **({"after_passes": after} if after else {}),
                "exit_mean": self.exit_mean, "exit_sd": self.exit_sd,
                "bed_mean": self.bed_mean,
                "bed_mean_by_cell": [None if not np.isfinite(x) else float(x)
                                     for x in self.bed_mean_by_cell]}


def _in_range(value: float, law) -> float:
    """``value`` moved onto its law's range (a conversion's [0, 1], an activity's
    [0, inf)) where it lies beyond it by round-off (1e-12 of the range's scale) alone: a
    carried conversion's exit mean came out 1.0000000000000007."""
    low, high = getattr(law, "initial_range", (None, None))
    tol = 1e-12 * max(1.0, abs(value))
    if high is not None and high < value <= high + tol:
        return float(high)
    if low is not None and low - tol <= value < low:
        return float(low)
    return value


#: where the landing matrix's rows sum to 1 within this, every residence is taken to land in
#: a kept entry state (the rest is the lap-deficit truncation's loss); beyond it, some
#: residences end in traps, and a carried property is followed among the survivors
SURVIVAL_TOL = 1e-6
#: the relative size of E[v^2] below which the exit variance E[v^2] - E[v]^2 is round-off
#: (an exit SD below 1e-6 of the value's scale is printed as 0)
ROUND_OFF = 1e-12
#: where E[v^2] exceeds the variance E[v^2] - E[v]^2 by more than this (four of the sixteen
#: digits lost), the exit SD is computed again from the moments of v - E[v]
CENTRE_ABOVE = 1e4
#: an exit SD computed from the moments of v - E[v] below this share of |E[v]| is zero
CENTRED_ROUND_OFF = 1e-12


def residence_chain(model, direction: str | None = None, deficit_levels: int | None = None,
                    landings: bool = False, entry=None) -> tuple:
    """The absorbing chain of a model's residences, on the states from which an exit can be
    reached (module docstring).

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"}, optional
        A periodic riser's residences: from passes up through the top or, for a net
        downflow, down through the bottom (the roles of the two passes swapped, entered
        with the downward exact RTD's entry distribution); default the model's
        ``flow_direction``. Ignored for an open riser.
    deficit_levels : int, optional
        K, the lap deficits kept: by default those of the model's exact RTD (as deep as
        its residences fall, :func:`~cfbmarkov.markov.first_passage.exact_rtd`); given, the
        entry distribution is that of the exact RTD on K deficits, computed here and not
        cached (a bootstrap resample's). Ignored for an open riser.
    landings : bool, optional
        Also return where each residence lands (a periodic riser's): the next residence's
        entry state.
    entry : array_like of float, shape (S,), optional
        A periodic riser's entry distribution to start the residences from instead of the
        model's own (a bootstrap resample started from the fitted model's, as its RTD is:
        :func:`cfbmarkov.analysis.bootstrap.bootstrap_figures`). Ignored for an open riser.

    Returns
    -------
    q : scipy.sparse.csr_matrix, shape (n, n)
    r, e : ndarray of float64, shape (n,)
    state : ndarray of int64, shape (n,)
        The model's state of each transient state (a periodic riser's levels repeat them).
    levels : int
        Lap-deficit levels (1 for an open riser).
    landing : scipy.sparse.csr_matrix, shape (n, M)
        With ``landings`` (a periodic riser): the probability of leaving on the next lag
        and landing in each of the M entry states (r split by landing; its rows sum to r).
    entry_rows : ndarray of int64, shape (M,)
        With ``landings``: each entry state's transient state at level 0 (-1 where no exit
        can be reached from it: the particles landing there are trapped).
    level_rows : ndarray of int64, shape (S,)
        With ``landings``: every state's transient state at level 0 (-1 where none).

    Raises
    ------
    CfbmarkovError
        If the model has no residence (no exit, or every one trapped).
    """
    s = model.n_states
    if model.open_flow is not None:
        q = sp.csr_matrix(model.absorbing_matrix)
        r = np.asarray(model.open_flow.exit_probability, dtype=np.float64)
        e = model.open_flow.entry_distribution
        live = states_reaching(q, np.flatnonzero(r > 0))
        levels = 1
    else:
        direction = model.flow_direction if direction is None else direction
        if direction not in ("up", "down"):
            raise InputError(f"residence direction {direction!r}: up or down")
        p_up, p_down, p_stay = split_by_pass(sp.csr_matrix(model.transition_matrix),
                                             model.up_fraction, model.down_fraction)
        if direction == "down":      # the pass down through the bottom ends a residence
            p_up, p_down = p_down, p_up
        if deficit_levels is None:   # as deep as the exact RTD's residences fall
            exact = model.rtd(direction=direction)
        else:
            from cfbmarkov.markov.model_rtd import net_entry_flux

            exact = rtd_of_split_chain(p_up, p_down, p_stay, model.lag, int(deficit_levels),
                                       entry_flux=net_entry_flux(model, direction))
        if entry is None:
            entry = exact.entry_distribution
        else:
            entry = np.asarray(entry, dtype=np.float64)
            if entry.shape != (s,):
                raise InputError(f"entry distribution of shape {entry.shape}: one value per "
                                 f"state ({s})")
        levels = exact.deficit_levels + 1
        q, r = deficit_matrix(p_up, p_down, p_stay, levels)
        live = _live_levels(p_up, p_down, p_stay, levels, r > 0)
        e = np.zeros(s * levels)
        e[:s] = entry
    keep = np.flatnonzero(live)
    e = e[keep]
    if not e.sum() > 0:
        raise InputError("no particle that enters can leave in the model: every residence is "
                         "trapped")
    state = np.tile(np.arange(s), levels)[keep]
    chain = (sp.csr_matrix(q)[keep][:, keep], r[keep], e / e.sum(), state, levels)
    if model.open_flow is not None:
        chain = _with_entry_delay(chain, model)
    if not landings:
        return chain
    if model.open_flow is not None:
        raise InputError("an open riser's residences do not land back in it")
    entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
    landing = sp.vstack([sp.csr_matrix(p_up)[:, entries],
                         sp.csr_matrix((s * (levels - 1), entries.size))]).tocsr()[keep]
    position = -np.ones(s * levels, np.int64)
    position[keep] = np.arange(keep.size)
    return (*chain, landing, position[entries], position[:s])


def _with_entry_delay(chain: tuple, model) -> tuple:
    """An open riser's residence chain with the lags between the inlet and a particle's
    first state (:func:`~cfbmarkov.markov.model_rtd.entry_delay`: a state space with memory
    gives a particle its first state a lag after it is first seen): a copy of the states
    ahead of them, entered with the entry distribution, each moving to its state with
    probability 1 and exiting never, so that a residence runs from the inlet as the data's
    do. A copy carries its state's law: over the delay the rate is taken as the entry
    state's (exact for a rate the same in every cell)."""
    from cfbmarkov.markov.model_rtd import entry_delay

    q, r, e, state, levels = chain
    for _ in range(entry_delay(model)):
        n = q.shape[0]
        q = sp.bmat([[sp.csr_matrix((n, n)), sp.identity(n, format="csr")],
                     [sp.csr_matrix((n, n)), q]], format="csr")
        r = np.concatenate([np.zeros(n), r])
        e = np.concatenate([e, np.zeros(n)])
        state = np.concatenate([state, state])
    return q, r, e, state, levels


def _bed_cells(model, row_cell: np.ndarray, n_rows: int) -> np.ndarray:
    """The cell each row of a residence chain counts in for the bed's means per cell: its
    state's, but for the copies :func:`_with_entry_delay` puts ahead of an open riser's
    states, which count at the inlet, in the bottom row's cell below their state's (where
    a prediction shows its newcomers, :func:`~cfbmarkov.markov.prediction.with_inlet_frames`,
    and where the data's particles are over that lag)."""
    if model.open_flow is None:
        return row_cell
    from cfbmarkov.markov.model_rtd import entry_delay

    delay = entry_delay(model)
    if not delay:
        return row_cell
    copies = n_rows - (n_rows >> delay)     # each lag of delay doubles the chain's rows
    row_cell = np.array(row_cell)
    row_cell[:copies] %= model.state_space.cells_per_row
    return row_cell


def exact_kinetics(model, kinetics: Kinetics | StateKinetics, cell_fields=None,
                   direction: str | None = None, deficit_levels: int | None = None,
                   entry=None) -> dict[str, PropertyAnswer]:
    """Exact answers of every property of linear kinetics on a model.

    Parameters
    ----------
    model : MarkovModel
        The fitted chain (open or periodic riser).
    kinetics : Kinetics or StateKinetics
        The properties (resolved on ``model.state_space`` where a :class:`Kinetics`).
    cell_fields : CellFields, optional
        For parameters given as functions of the fitting window's cell fields (default: the
        ones the model stores, :attr:`MarkovModel.cell_fields`).
    direction : {"up", "down"}, optional
        A periodic riser's residences (:func:`residence_chain`): from passes up through the
        top or down through the bottom (a net downflow); default the model's
        ``flow_direction``.
    deficit_levels : int, optional
        The lap deficits kept (:func:`residence_chain`); default those of the model's
        exact RTD.
    entry : array_like of float, shape (S,), optional
        A periodic riser's entry distribution instead of the model's own
        (:func:`residence_chain`): a bootstrap resample's answers from the fitted model's.

    Returns
    -------
    dict of str to PropertyAnswer
        By property name, in order. A ``reference`` start gives the answers of ``entry``
        (in a steady state every residence starts at the inlet).

    Raises
    ------
    InputError
        For a non-linear (custom) law, a carried property with no relaxation, a model
        without residences, something other than a fitted model, or ``deficit_levels`` that
        is not a whole number >= 0.
    """
    if not hasattr(model, "state_space") or not hasattr(model, "transition_matrix"):
        raise InputError(f"exact_kinetics: {model!r} is not a fitted model; give one "
                         "(cfbmarkov.markov.MarkovModel.load(PATH) for a model file)")
    if deficit_levels is not None and (not isinstance(deficit_levels, numbers.Integral)
                                       or isinstance(deficit_levels, bool)
                                       or deficit_levels < 0):
        raise InputError(f"deficit_levels = {deficit_levels!r}: a whole number of lap "
                         "deficits >= 0, or None (those of the model's exact RTD)")
    sk = on_states(kinetics, model.state_space,
                   model.cell_fields if cell_fields is None else cell_fields)
    for name, linear, law in zip(sk.names, sk.linear, sk.laws):
        if not linear:
            raise InputError(f"property {name}: law {law.key} has no exact answer; run the "
                             "Monte Carlo (react --init RUN --start T --duration D -o OUT)")
    where = f"{sk.source}: " if getattr(sk, "source", "") else ""
    if model.open_flow is not None and "carried" in sk.starts:
        name = sk.names[list(sk.starts).index("carried")]
        raise InputError(f"{where}property {name}: a carried property needs a periodic riser: "
                         "particles that leave an open riser do not come back (use start = "
                         "entry)")
    carries = "carried" in sk.starts
    q, r, e, state, _, *landed = residence_chain(model, direction, deficit_levels,
                                                 landings=carries, entry=entry)
    landed = landed[:2]         # where residences land, and the entry states' rows
    a_all, b_all = sk.over(model.lag)
    c_all = -np.expm1(-np.asarray(sk.rate, dtype=np.float64) * model.lag)    # 1 - a, exact
    space = model.state_space
    cell = np.asarray(space.cell_of_state, dtype=np.int64)
    out = {}
    lu_q = _lu(sp.identity(q.shape[0], format="csc") - q)
    occupancy = lu_q.solve(e, trans="T")       # lags spent in each state per entry
    row_cell = _bed_cells(model, cell[state], q.shape[0])
    for i, name in enumerate(sk.names):
        a, b, c = a_all[i][state], b_all[i][state], c_all[i][state]
        occ = occupancy
        factors = _factors(q, a, c, lu_q)       # shared by the centred moments below
        if sk.starts[i] == "carried":
            try:
                m = carried_moments(q, r, e, a, b, *landed, lu_q, c, factors)
            except InputError as exc:
                raise InputError(f"{where}property {name}: {exc}") from None
            v0, second = m.carried()
            mean = v0
            entering = np.zeros(q.shape[0])     # the value's mass entering by entry state
            entering[landed[1][m.kept]] = m.mean_by_entry
            if m.survivors is not None:         # the bed of the particles still circulating
                start = np.zeros(q.shape[0])
                start[landed[1][m.kept]] = m.survivors
                occ = lu_q.solve(start, trans="T")
            # mu = (u + (nu o b) Q) (I - D Q)^-1 (module docstring)
            values = m.entering_mass(entering + q.T @ (occ * b))
        else:
            m = exit_moments(q, r, e, a, b, lu_q, c, factors)
            v0 = float(sk.initial[i])
            mean, second = m.exit_mean(v0), m.exit_second(v0)
            values = v0 * m.mass_per_start + m.mass_rest
        variance, shifted = second - mean * mean, None
        # the variance is round-off where every exit value is alike (a carried value at a
        # uniform target): below ROUND_OFF of E[v^2], the values' own scale, it is zero
        floor = ROUND_OFF * abs(second)
        if abs(second) > CENTRE_ABOVE * max(variance, 0.0) and mean != 0.0:
            # values far from zero against their spread (a temperature of 1e8 +- 50): E[v^2]
            # - E[v]^2 keeps few or no digits. The same moments of w = v - mean, whose law
            # is w' = a w + (b - (1 - a) mean), lose none
            centred = b - c * mean
            if sk.starts[i] == "carried":
                shifted = carried_moments(q, r, e, a, centred, *landed, lu_q, c, factors)
                mw, sw = shifted.carried()
            else:
                mc = exit_moments(q, r, e, a, centred, lu_q, c, factors)
                mw, sw = mc.exit_mean(v0 - mean), mc.exit_second(v0 - mean)
            # what is left of w's round-off: b - (1 - a) mean and v0 - mean carry an
            # absolute error of a few ulps of the mean, so an SD within 1e-12 of it is zero
            variance, floor = sw - mw * mw, (CENTRED_ROUND_OFF * mean) ** 2
        sd = float(np.sqrt(variance)) if variance > floor else 0.0
        mass = np.bincount(state, values, minlength=model.n_states)
        count = np.bincount(state, occ, minlength=model.n_states)
        by_state = np.divide(mass, count, out=np.full(mass.size, np.nan), where=count > 0)
        cmass = np.bincount(row_cell, values, minlength=space.n_cells)
        ccount = np.bincount(row_cell, occ, minlength=space.n_cells)
        by_cell = np.divide(cmass, ccount, out=np.full(cmass.size, np.nan), where=ccount > 0)
        centre = float(mean) if shifted is not None else 0.0
        mean = _in_range(mean, sk.laws[i])
        out[name] = PropertyAnswer(name, sk.starts[i], float(v0), float(mean), sd,
                                   float(mass.sum() / count.sum()), by_state, by_cell,
                                   float(sk.initial[i]), m, shifted, centre)
    return out


def windowed_exit_means(model, kinetics: Kinetics | StateKinetics, length: float,
                        cell_fields=None, direction: str | None = None,
                        history: float = 0.0, occupancy=None) -> dict[str, float]:
    """The mean exit value per residence as a window of ``length`` seconds observes it:
    each residence of n lags weighted by the number of places it fits in the window (a
    periodic riser's counted from the window's first frame: Notes).

    A window of M = length / lag lags sees a residence of n lags that starts at one of its
    lag boundaries 1 .. M - n and ends inside it, M - n ways; in a steady state the exits
    of a window are therefore the chain's exits weighted by w_n = max(M - n, 0), which
    favours short residences. With a ``history`` of H = history / lag lags (the exits
    inside the window whose residence began at most H lags before it, as
    :func:`cfbmarkov.analysis.kinetics_reference.reference_kinetics` counts them with a
    history), a residence of n lags ends at one of the window's M lag boundaries from
    n + 1 - H on, so

        w_n = min(M, M + H - n), clipped at 0,

    every residence up to H lags counted at its full rate M and none longer than M + H.
    With the first-passage masses p_n = e Q^(n-1) r and value
    masses m_n = E[v_exit 1{exit at n}], propagated lag by lag (u <- a o u + b o p, exit
    through r, move by Q; the affine maps of :meth:`StateKinetics.over
    <cfbmarkov.kinetics.StateKinetics.over>`),

        windowed mean = sum_n w_n m_n / sum_n w_n p_n.

    This is the answer to compare with exit values observed over a finite window (the
    reference's paths, an observed RTD), with the weights of the RTD as a window observes
    it (:meth:`ResidenceTimeDistribution.in_window
    <cfbmarkov.markov.first_passage.ResidenceTimeDistribution.in_window>` without a
    history); as ``length`` or ``history`` grows it tends to :func:`exact_kinetics`' exit
    mean.

    Parameters
    ----------
    model : MarkovModel
        The fitted chain (open or periodic riser).
    kinetics : Kinetics or StateKinetics
        The properties (linear laws). A ``carried`` property (its value at entry that of
        the previous pass) is left out of the result; the others start at their entry
        value.
    length : float
        The window's length (s), at least one lag.
    cell_fields : CellFields, optional
        As :func:`exact_kinetics`.
    direction : {"up", "down"}, optional
        As :func:`exact_kinetics`.
    history : float, optional
        Seconds before the window that an exit's residence may have begun in (>= 0; 0:
        residences wholly inside the window).
    occupancy : array_like of float, shape (S,), optional
        A periodic riser's: where the particles are when the records begin to be counted
        (the window's start less the history); default
        :func:`~cfbmarkov.markov.model_rtd.window_start_occupancy`.

    Notes
    -----
    A periodic riser's window counts the records of each particle's lap counter from the
    first frame it reads, as the reference's paths do: a particle below its own past
    maximum there makes records that are not its history's, so the exits are weighted as
    :func:`~cfbmarkov.markov.first_passage.window_rtd` weights residences (a renewal of the
    records from ``occupancy`` on the lap-deficit levels, landing on deficit 0 again, and
    the backward equations of the value masses: A_1 = a r, B_1 = b r,
    A_(k+1) = a (Q A_k), B_(k+1) = b (Q A_k) + Q B_k, the exit mean of a residence of k lags
    from entry state e being v0 A_k(e) + B_k(e)); the weights w_n above are that count
    where no particle falls through the bottom.

    Returns
    -------
    dict of str to float
        The windowed exit mean of each property but the carried ones, by name.

    Raises
    ------
    InputError
        For a non-linear law, a window shorter than a lag, a negative or non-finite
        history, or a model without residences.
    """
    sk = on_states(kinetics, model.state_space,
                   model.cell_fields if cell_fields is None else cell_fields)
    for name, linear, law in zip(sk.names, sk.linear, sk.laws):
        if not linear:
            raise InputError(f"property {name}: law {law.key} has no exact answer")
    steps = int(round(float(length) / model.lag))
    if steps < 1:
        raise InputError(f"window of {length:g} s is shorter than the lag {model.lag:g} s")
    if not (np.isfinite(history) and history >= 0):
        raise InputError(f"history {history!r} s: a finite number of seconds >= 0")
    back = int(round(float(history) / model.lag))
    if model.open_flow is None:
        return _windowed_records(model, sk, steps, back, direction, occupancy)
    q, r, e, state, _ = residence_chain(model, direction)
    qt = q.T.tocsr()
    a_all, b_all = sk.over(model.lag)
    a, b = a_all[:, state], b_all[:, state]                      # [P, n]
    p = e.copy()
    u = np.asarray(sk.initial, dtype=np.float64)[:, None] * e[None, :]
    weighted_value = np.zeros(sk.n_properties)
    weighted_prob = 0.0
    for n in range(1, steps + back):
        u = a * u + b * p[None, :]
        w = min(steps, steps + back - n)
        weighted_value += w * (u @ r)
        weighted_prob += w * float(p @ r)
        p = qt @ p
        u = (qt @ u.T).T
    if not weighted_prob > 0:
        raise InputError(f"no residence of the model fits a window of {length:g} s")
    return {name: float(weighted_value[i] / weighted_prob) for i, name in enumerate(sk.names)
            if sk.starts[i] != "carried"}


def _windowed_records(model, sk: StateKinetics, steps: int, back: int,
                      direction: str | None, occupancy) -> dict[str, float]:
    """:func:`windowed_exit_means` of a periodic riser: the records counted from the first
    frame read (``back`` lags before a window of ``steps`` lags), the particles starting in
    ``occupancy`` on deficit 0 (its Notes)."""
    from cfbmarkov.markov.model_rtd import window_start_occupancy

    q, r, _, state, _, landing, entry_rows, level_rows = residence_chain(
        model, direction, landings=True)
    start = window_start_occupancy(model, direction) if occupancy is None else occupancy
    start = np.clip(np.asarray(start, dtype=np.float64).ravel(), 0.0, None)
    if start.shape != (model.n_states,) or not start.sum() > 0:
        raise InputError(f"occupancy: non-negative weights of shape ({model.n_states},) with "
                         "some mass")
    span = steps + back                         # lags read, from the first frame
    n = q.shape[0]
    v = np.zeros(n)
    here = level_rows >= 0
    v[level_rows[here]] = start[here] / start.sum()
    qt = q.T.tocsr()
    landing_t = landing.T.tocsr()
    into = entry_rows >= 0
    landed = np.zeros((span, entry_rows.size))      # landed[s - 1]: by the record of lag s
    for k in range(span - 1):
        landed[k] = landing_t @ v
        v = qt @ v
        v[entry_rows[into]] += landed[k][into]
    cumulative = np.vstack([np.zeros(entry_rows.size), np.cumsum(landed, axis=0)])
    a_all, b_all = sk.over(model.lag)
    a, b = a_all[:, state], b_all[:, state]                      # [P, n]
    initial = np.asarray(sk.initial, dtype=np.float64)[:, None]
    ends = r.copy()                                               # b_k
    scaled, added = a * r[None, :], b * r[None, :]                # A_k, B_k
    weighted_value = np.zeros(sk.n_properties)
    weighted_prob = 0.0
    rows = np.where(into, entry_rows, 0)
    for k in range(1, span):
        # residences of k lags that begin at a record of lag s >= 1 and end inside the
        # window: back < s + k <= span
        lo, hi = max(1, back + 1 - k), span - k
        if hi >= lo:
            begun = np.where(into, cumulative[hi] - cumulative[lo - 1], 0.0)
            weighted_prob += float(begun @ ends[rows])
            weighted_value += (initial * scaled[:, rows] + added[:, rows]) @ begun
        moved = (q @ scaled.T).T
        added = b * moved + (q @ added.T).T
        scaled = a * moved
        ends = q @ ends
    if not weighted_prob > 0:
        raise InputError(f"no residence of the model fits a window of {steps * model.lag:g} s")
    return {name: float(weighted_value[i] / weighted_prob) for i, name in enumerate(sk.names)
            if sk.starts[i] != "carried"}
