"""Connectivity of a chain: closed classes, the largest strongly connected set, and which
states can reach a trap (pure functions on the graph P_ij > 0 or C_ij > 0).

A chain fitted on particles that never meet (two tracers in different columns, say) is
reducible: it has several closed classes, and quantities such as the stationary entry
distribution are not unique. A state first entered in the fitting window's last frame has
no outgoing transition and becomes a trap (P_ii = 1). Markov-state-model software reports
both (deeptime's and PyEMMA's connected sets); these functions do so here.

References
----------
J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand (1960), Ch. II
(classification of states). deeptime ``TransitionCountModel.connected_sets``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from cfbmarkov._blas import one_blas_thread


def _graph(matrix) -> sp.csr_matrix:
    graph = sp.csr_matrix(matrix)
    graph.eliminate_zeros()
    return graph


def closed_classes(matrix, *, min_size: int = 1) -> list[np.ndarray]:
    """The closed classes of the chain: strongly connected sets of states that no
    transition leaves, largest first.

    Parameters
    ----------
    matrix : array_like or sparse, shape (S, S)
        The transition matrix P (or counts: only P_ij > 0 matters).
    min_size : int
        Leave out classes with fewer states (2 leaves out single traps P_ii = 1).

    Returns
    -------
    list of ndarray of int64
        The states of each class.
    """
    graph = _graph(matrix)
    n, labels = connected_components(graph, directed=True, connection="strong")
    rows = np.repeat(np.arange(graph.shape[0]), np.diff(graph.indptr))
    leaving = labels[rows] != labels[graph.indices]
    closed = np.ones(n, bool)
    closed[labels[rows[leaving]]] = False
    out = [np.flatnonzero(labels == c) for c in np.flatnonzero(closed)]
    out = [c for c in out if c.size >= min_size]
    return sorted(out, key=lambda c: (-c.size, int(c[0])))


def largest_connected_set(counts) -> np.ndarray:
    """States of the largest strongly connected set of the count graph C_ij > 0 (sorted),
    the set deeptime and PyEMMA estimate on by default.

    Parameters
    ----------
    counts : array_like or sparse, shape (S, S)

    Returns
    -------
    ndarray of int64
    """
    graph = _graph(counts)
    n, labels = connected_components(graph, directed=True, connection="strong")
    sizes = np.bincount(labels, minlength=n)
    # ties: the set holding the most transitions
    weight = np.bincount(labels[np.repeat(np.arange(graph.shape[0]), np.diff(graph.indptr))],
                         weights=graph.data, minlength=n)
    best = max(range(n), key=lambda c: (sizes[c], weight[c]))
    return np.flatnonzero(labels == best).astype(np.int64)


def states_reaching(matrix, targets) -> np.ndarray:
    """States from which the chain can reach any of ``targets`` (the targets included).

    One breadth-first search of the reversed graph of P_ij > 0 (stored zeros are no
    transitions), from a virtual node joined to every target.

    Parameters
    ----------
    matrix : array_like or sparse, shape (S, S)
    targets : array_like of int
        Indices of the target states.

    Returns
    -------
    ndarray of bool, shape (S,)
    """
    graph = _graph(matrix)
    n = graph.shape[0]
    targets = np.unique(np.asarray(targets, dtype=np.int64).ravel())
    reach = np.zeros(n, bool)
    if targets.size == 0:
        return reach
    hub = sp.csr_matrix((np.ones(targets.size), (np.full(targets.size, n), targets)),
                        shape=(n + 1, n + 1))
    reverse = sp.bmat([[graph.T, None], [None, sp.csr_matrix((1, 1))]], format="csr") + hub
    order = breadth_first_order(reverse, n, directed=True, return_predecessors=False)
    reach[order[order < n]] = True
    return reach


def restrict_to_set(matrix: np.ndarray, states: np.ndarray) -> np.ndarray:
    """P with the transitions from ``states`` to states outside them removed and those rows
    renormalised (rows outside the set are kept as they are).

    Parameters
    ----------
    matrix : ndarray of float64, shape (S, S)
    states : ndarray of int

    Returns
    -------
    ndarray of float64, shape (S, S)
        A new stochastic matrix; a row of the set that had all its mass outside it keeps
        its particles in place.
    """
    p = np.array(matrix, dtype=np.float64)
    inside = np.zeros(p.shape[0], bool)
    inside[np.asarray(states, dtype=np.int64)] = True
    rows = np.flatnonzero(inside)
    p[np.ix_(rows, np.flatnonzero(~inside))] = 0.0
    sums = p[rows].sum(axis=1)
    ok = sums > 0
    p[rows[ok]] /= sums[ok][:, None]
    p[rows[~ok], :] = 0.0
    p[rows[~ok], rows[~ok]] = 1.0
    return p


def long_run_distribution(matrix: np.ndarray, classes: list[np.ndarray],
                          occupancy: np.ndarray) -> np.ndarray:
    """Where the mass ``occupancy`` ends up in a reducible chain: each closed class gets the
    mass already in it plus what the transient states are absorbed into it with, spread by
    the class's own stationary distribution.

    Parameters
    ----------
    matrix : ndarray of float64, shape (S, S)
        P.
    classes : list of ndarray of int
        Its closed classes (:func:`closed_classes`).
    occupancy : ndarray of float64, shape (S,)
        The starting mass (e.g. particle-frames per state); uniform where it is all zero.

    Returns
    -------
    ndarray of float64, shape (S,)
        Sums to 1; zero on transient states.
    """
    p = np.asarray(matrix, dtype=np.float64)
    s = p.shape[0]
    v = np.asarray(occupancy, dtype=np.float64).ravel().copy()
    if not v.sum() > 0:
        v = np.ones(s)
    v /= v.sum()
    in_class = np.zeros(s, bool)
    for members in classes:
        in_class[members] = True
    transient = np.flatnonzero(~in_class)
    carried = np.zeros(s)
    if transient.size:
        # w = v_T (I - P_TT)^-1: expected visits; w P_T,c is the mass absorbed into c
        q = p[np.ix_(transient, transient)]
        w = np.linalg.solve((np.eye(transient.size) - q).T, v[transient])
        carried = w @ p[transient]
    out = np.zeros(s)
    for members in classes:
        mass = v[members].sum() + carried[members].sum()
        if mass <= 0:
            continue
        block = p[np.ix_(members, members)]
        if members.size == 1:
            pi = np.ones(1)
        else:
            values, vectors = np.linalg.eig(block.T)
            pi = np.abs(vectors[:, int(np.argmin(np.abs(values - 1.0)))].real)
            pi /= pi.sum()
        out[members] = mass * pi
    return out / out.sum()


def stationary_distribution(matrix: np.ndarray, occupancy: np.ndarray) -> np.ndarray:
    """The long-run distribution of P, pi P = pi.

    One closed class: the left eigenvector of P for eigenvalue 1. A reducible chain (several
    closed classes, traps P_ii = 1 included) has no unique one: ``occupancy`` is carried
    into the closed classes by their absorption probabilities, and each class holds its own
    stationary distribution with that mass (:func:`long_run_distribution`).

    Parameters
    ----------
    matrix : ndarray of float64, shape (S, S)
        P.
    occupancy : ndarray of float64, shape (S,)
        The mass of a reducible chain (e.g. particle-frames per state); uniform where it is
        all zero.

    Returns
    -------
    ndarray of float64, shape (S,)
        Sums to 1.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton
    (1960) (Ch. III absorbing chains, IV-V regular and ergodic chains).
    """
    classes = closed_classes(matrix)
    if len(classes) > 1:
        return long_run_distribution(matrix, classes, occupancy)
    with one_blas_thread():          # BLAS threads only contend on a dense eig here
        values, vectors = np.linalg.eig(matrix.T)
    lead = int(np.argmin(np.abs(values - 1.0)))
    pi = np.abs(vectors[:, lead].real)
    return pi / pi.sum()


__all__ = ["closed_classes", "largest_connected_set", "long_run_distribution",
           "restrict_to_set", "stationary_distribution", "states_reaching"]
