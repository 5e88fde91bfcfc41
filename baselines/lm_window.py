"""The recent part of the LM mappers' graph, kept by step, for warm starts and fixed-lag solves.

:class:`baselines.factor_graph.BatchState` hands every batch of new factors to
:class:`StepChunks`, which files them by the steps that own them (a *chunk*: the odometry and
bearings of the steps since the previous batch; a late landmark's buffered bearings go to the
chunk of their step). A window ``x_b .. x_{T-1}`` (``b + 1`` a chunk's first step) is then the
union of the newest chunks, taken without a loop over factors, plus a prior holding ``x_b``.
Two uses (issue 14 items 1-2):

* **warm start** (:meth:`StepChunks.warm_solve`): before a whole-graph solve, the poses added
  since the last solution (predicted by dead reckoning, often centimetres off) are solved with
  the landmarks held near their current points by an isotropic prior of
  ``warm_presolve_sigma_m``: a problem of ``solve_every`` poses, after which the whole-graph LM
  starts near its minimum and needs fewer iterations;
* **fixed-lag solve** (:meth:`StepChunks.window`): on long recordings, the last ``lag_steps``
  poses and the landmarks they see. The older steps' factors are *eliminated* into a marginal:
  as the window moves on, the chunks that leave it are linearised at the current values with
  the marginal so far and every pose but the new boundary pose eliminated
  (``eliminatePartialMultifrontal``), leaving a Gaussian on the boundary pose and the
  landmarks (``LinearContainerFactor``). A window solve therefore costs the window plus a
  dense block of ``2 L + 3`` unknowns for ``L`` landmarks, not the history, and is the
  whole-graph Gauss-Newton solution to first order in the values the old steps were
  linearised at; after each whole-graph solve the marginal is rebuilt from every chunk at the
  new values. Bearings filed after their chunk was eliminated (a landmark entering late) are
  folded by conditioning on the held poses (:func:`fold_bearings`). Past
  ``lag_marginal_landmarks`` landmarks (large maps, where a dense marginal would cost
  ``O(L^3)`` per iteration), or when an elimination fails (``marginal_failure``), the
  marginal is given up for *conditional folds*: each landmark's
  bearings from the older (held) poses folded into one Gaussian prior (:func:`fold_bearings`),
  grown as steps leave the window, redone from all its old
  bearings when its point has moved more than ``refold_m`` from where it was folded, and all
  reset after a whole-graph solve; the held boundary pose is then fixed by a prior.

With ``keep_conditionals`` (the windows of ``gtsam-batch``, ``oracle``, ``hybrid`` and
``gtsam-isam2``) the eliminated poses are kept as Gaussian conditionals on the poses and
landmarks left (the cliques of the same elimination), and :meth:`StepChunks.back_substitute`
moves the held poses with a window's solution: the whole-graph Gauss-Newton solution to first
order, at the cost of one back-substitution, without solving the older steps again.
"""

from __future__ import annotations

import bisect
from typing import Callable, Iterable, Sequence

import gtsam
import numpy as np

from bomgraph.angles import angle_residual
from bomgraph.geometry import bearing_offsets
from bomgraph.stream import StreamHeader

from .lm_report import GTSAM_ERRORS, gtsam_error_line, lm_params
from .bearing_graph import (FactorGraphConfig, bearing_noise, landmark_key, pose_key,
                            prior_factor)
from .graph_values import key_landmark_ids, landmark_keys, points_at


_POSE_CHARS = (ord("x"), ord("m"))


def _is_landmark(key: int) -> bool:
    """Every key of the graph is a pose (``x``, ``m``) or a landmark
    (:func:`baselines.graph_values.landmark_key`, wide ids included)."""
    return (int(key) >> 56) not in _POSE_CHARS


class StepChunks:
    """The factors of the recent steps by chunk, and the folded old bearings of each landmark.

    Parameters
    ----------
    header : StreamHeader
    config : FactorGraphConfig
        ``sigma_floor_*`` (the boundary prior), ``bearing_cauchy_k``, ``lag_steps``.
    keep_conditionals : bool
        Keep the eliminated poses' conditionals for :meth:`back_substitute`.
    """

    #: A landmark folded at a point farther than this (m) from its current one is refolded.
    refold_m = 1e-3

    def __init__(self, header: StreamHeader, config: FactorGraphConfig,
                 keep_conditionals: bool = False) -> None:
        self.header = header
        self.config = config
        self._starts: list[int] = []                       # first step of each chunk
        self._graphs: list[gtsam.NonlinearFactorGraph] = []
        self._noise = bearing_noise(header, cauchy_k=config.bearing_cauchy_k)
        fm, fr = config.sigma_floor_m, config.sigma_floor_rad
        self._hold = gtsam.noiseModel.Diagonal.Sigmas([fm, fm, fr])
        # folded old bearings: landmark id -> [information (2, 2), information vector (2,),
        # point folded at (2,)]; bearings of steps < _folded_to are in the fold
        self._fold: dict[int, list[np.ndarray]] = {}
        self._folded_to = 0
        # the marginal (module docstring): chunks [0, _n_marg) eliminated into _marg, a graph
        # of LinearContainerFactors on the landmarks and the last eliminated boundary pose;
        # _late: bearings filed after their chunk was eliminated (folded by conditioning)
        self.marginal = config.lag_marginal_landmarks > 0
        self.marginal_failure: str | None = None   # why the marginal was given up, if it failed
        self._n_marg = 0
        self._marg = gtsam.NonlinearFactorGraph()
        self._marg_landmarks = 0
        self._late: list[tuple[int, int, float]] = []
        # keep_conditionals: (Bayes net of the eliminated poses, their linearisation points,
        # its parent landmarks' keys (n,) and points (n, 2), the held pose's key and point),
        # oldest first
        self._keep = keep_conditionals
        self._conditionals: list[tuple[gtsam.GaussianBayesNet, gtsam.Values, list[int],
                                       np.ndarray, int, gtsam.Pose2]] = []

    # -- filing -----------------------------------------------------------------------------
    def add(self, first_step: int, core: gtsam.NonlinearFactorGraph,
            entries: dict[int, tuple[Sequence[int], Sequence[float]]]) -> None:
        """File a batch: ``core`` (the factors of steps ``first_step ..``) as a new chunk and
        the buffered bearings ``entries`` (landmark id -> (steps, bearings)) of the landmarks
        that entered now, each in its step's chunk (dropped if that chunk is gone; a
        bearing of a step already folded is added to its landmark's fold at the next
        window). Chunks older than two windows are forgotten."""
        self._starts.append(int(first_step))
        self._graphs.append(core)
        oldest = self._starts[0]
        for lid, (ts, bs) in entries.items():
            for t, b in zip(ts, bs):
                if t >= oldest:
                    self._file(int(t), int(lid), float(b))
        keep = first_step - 2 * self.config.lag_steps
        while not self.marginal and len(self._starts) > 1 and self._starts[1] <= keep:
            self._starts.pop(0)
            self._graphs.pop(0)

    def _file(self, t: int, lid: int, bearing: float) -> None:
        """File one bearing into its step's chunk, or among the late bearings if that chunk
        is already in the marginal."""
        k = bisect.bisect_right(self._starts, t) - 1
        if k < self._n_marg:
            self._late.append((t, lid, bearing))
        else:
            self._graphs[k].add(gtsam.BearingFactor2D(pose_key(t), landmark_key(lid),
                                                      gtsam.Rot2(bearing), self._noise))

    def boundary(self, n_steps: int, lag_steps: int) -> int | None:
        """The held pose ``b`` of a window of at least ``lag_steps`` poses ending at step
        ``n_steps - 1`` (``b + 1`` a chunk's first step), or None if no chunk starts late
        enough to leave a pose before it."""
        k = bisect.bisect_right(self._starts, max(n_steps - lag_steps, 1)) - 1
        if k < 0 or self._starts[k] < 1:
            return None
        return self._starts[k] - 1

    def newest_boundary(self) -> int | None:
        """The held pose of the newest chunk alone (the last solved pose), or None."""
        return self._starts[-1] - 1 if self._starts and self._starts[-1] >= 1 else None

    def _factors(self, b: int) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        for g in self._graphs[bisect.bisect_right(self._starts, b):]:
            graph.push_back(g)
        return graph

    @staticmethod
    def _values(keys: Iterable[int], source: gtsam.Values) -> gtsam.Values:
        """The entries of ``source`` for ``keys`` (unique), copied in one ``extract``."""
        return source.extract([int(k) for k in keys])

    # -- warm start -------------------------------------------------------------------------
    def warm_solve(self, values: gtsam.Values, held: gtsam.Values, sigma_m: float,
                   tol: float) -> tuple[gtsam.Values | None, int]:
        """The warm start (module docstring): the poses of the newest chunk solved against
        the landmarks, each held at its point in ``values`` by an isotropic prior of
        ``sigma_m``, the last solved pose held at ``held``. Returns that solution (the newest
        chunk's poses and the landmarks they see), to lay over ``values`` (whole, or only a
        window's part: :meth:`window`'s ``overlay``), and the LM iterations taken; None if
        there is no earlier chunk, or the solve failed (0 iterations) or did not lower its
        error."""
        b = self.newest_boundary()
        if b is None:
            return None, 0
        graph = self._factors(b)
        graph.add(gtsam.PriorFactorPose2(pose_key(b), held.atPose2(pose_key(b)), self._hold))
        keys = list(graph.keyVector())
        noise = gtsam.noiseModel.Isotropic.Sigma(2, sigma_m)
        for k in keys:
            if _is_landmark(k):
                graph.add(gtsam.PriorFactorPoint2(k, values.atPoint2(k), noise))
        return self._lm(graph, self._values(keys, values), tol)

    def _lm(self, graph: gtsam.NonlinearFactorGraph, start: gtsam.Values, tol: float
            ) -> tuple[gtsam.Values | None, int]:
        params = lm_params(self.config)
        params.setRelativeErrorTol(tol)
        try:
            opt = gtsam.LevenbergMarquardtOptimizer(graph, start, params)
            e0 = opt.error()
            solved = opt.optimize()
        except GTSAM_ERRORS:
            return None, 0
        if not opt.error() <= e0:
            return None, int(opt.iterations())
        return solved, int(opt.iterations())

    # -- fixed-lag window -------------------------------------------------------------------
    def window(self, b: int, n_steps: int, initial: gtsam.Values, held: gtsam.Values,
               pose_at: Callable[[np.ndarray], np.ndarray],
               bearings: tuple[np.ndarray, np.ndarray, np.ndarray],
               landmark_ids: np.ndarray, fresh: Sequence[int],
               overlay: gtsam.Values | None = None
               ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The fixed-lag problem with held pose ``b`` (module docstring): factors and start.

        Parameters
        ----------
        initial : start of the window's variables; held : the current values (the held
        pose, the landmarks' points to fold at); pose_at : ``pose_at(ts)`` the current poses
        ``ts`` (k,), shape (k, 3);
        bearings : (owner (J,), id (J,), bearing (J,)) every bearing so far, owner sorted;
        landmark_ids : (n,) sorted, those in the graph; fresh : entered since the last solve;
        overlay : values laid over ``initial`` in the start (a :meth:`warm_solve` solution).
        """
        if self.marginal:
            self._marginalise(b, held)
        graph = self._factors(b)
        if self.marginal:
            graph.push_back(self._marg)
        else:
            graph.add(gtsam.PriorFactorPose2(pose_key(b), held.atPose2(pose_key(b)),
                                             self._hold))
        in_graph = np.asarray(graph.keyVector(), dtype=np.uint64)
        arr = np.union1d(key_landmark_ids(in_graph), np.asarray(fresh, dtype=np.int64))
        active = arr.tolist()
        keys = np.union1d(in_graph, landmark_keys(arr))
        if self.marginal:
            folds = self._late_folds(b, held, pose_at, active)
        else:
            self._fold_upto(b + 1, held, pose_at, bearings, landmark_ids, active)
            folds = [(i, *self._fold[i][:2]) for i in active if i in self._fold]
        if folds:
            # every fold's prior at once: H + (1e-12 + 1e-9 tr H) I, its mean H^-1 eta
            ids = np.array([f[0] for f in folds], dtype=np.int64)
            info = np.array([f[1] for f in folds]).reshape(-1, 2, 2)
            eta = np.array([f[2] for f in folds]).reshape(-1, 2)
            use = info.any(axis=(1, 2))
            ids, info, eta = ids[use], info[use], eta[use]
            h = info + (1e-12 + 1e-9 * (info[:, 0, 0] + info[:, 1, 1]))[:, None, None] \
                * np.eye(2)
            mean = np.linalg.solve(h, eta[:, :, None])[:, :, 0]
            for k, m, hk in zip(landmark_keys(ids).tolist(), mean, h):
                graph.add(gtsam.PriorFactorPoint2(k, m,
                                                  gtsam.noiseModel.Gaussian.Information(hk)))
        act = set(active)
        for p in self.header.priors:
            if p.i in act and p.j in act:
                graph.add(prior_factor(p))
        start = self._values(keys.tolist(), initial)
        if overlay is not None:
            over = np.intersect1d(np.asarray(overlay.keys(), dtype=np.uint64), keys)
            start.update(overlay.extract(over.tolist()))
        return graph, start

    def _marginalise(self, b: int, held: gtsam.Values) -> None:
        """Eliminate the chunks of steps <= ``b`` not yet in the marginal: their factors and
        the marginal, linearised at ``held``, with every pose but ``x_b`` eliminated, leave a
        Gaussian on ``x_b`` and the landmarks (LinearContainerFactors). Past
        ``lag_marginal_landmarks`` landmarks the marginal is given up for the conditional
        folds (:meth:`_fold_upto`) for the rest of the run."""
        j = bisect.bisect_right(self._starts, b)
        if j <= self._n_marg:
            return
        nl = gtsam.NonlinearFactorGraph(self._marg)
        for g in self._graphs[self._n_marg:j]:
            nl.push_back(g)
        keys = list(nl.keyVector())
        n_lm = sum(1 for k in keys if _is_landmark(k))
        if n_lm > self.config.lag_marginal_landmarks:
            self._give_up_marginal()
            return
        start = self._values(keys, held)
        hold = pose_key(b)
        gone = [k for k in keys if not _is_landmark(k) and k != hold]
        try:
            tree, rest = nl.linearize(start).eliminatePartialMultifrontal(gone)
        except GTSAM_ERRORS as exc:
            # a nearly indeterminate elimination: seen where a pose passed millimetres from a
            # landmark (its bearing's Jacobian ~1e6 times the others'; the whole system
            # positive definite at condition ~1e12). The conditional folds need no
            # elimination.
            self.marginal_failure = gtsam_error_line(exc)
            self._give_up_marginal()
            return
        if self._keep:
            lms = [k for k in keys if _is_landmark(k)]
            xy = np.array([start.atPoint2(k) for k in lms]).reshape(-1, 2)
            self._conditionals.append((_bayes_net(tree), self._values(gone, start), lms, xy,
                                       hold, start.atPose2(hold)))
        self._marg = gtsam.NonlinearFactorGraph()
        for i in range(rest.size()):
            f = rest.at(i)
            if f is not None:
                self._marg.add(gtsam.LinearContainerFactor(f, self._values(f.keys(), start)))
        self._n_marg = j
        self._marg_landmarks = n_lm

    def _give_up_marginal(self) -> None:
        """From now on the conditional folds (:meth:`_fold_upto`) instead of the marginal."""
        self.marginal, self._marg, self._late = False, gtsam.NonlinearFactorGraph(), []
        self.reset_folds()

    def back_substitute(self, current: gtsam.Values) -> gtsam.Values:
        """The eliminated poses given ``current`` (which holds every landmark and the newest
        held pose, e.g. a window's solution): newest conditionals first, each solved for its
        poses given its parents (the landmarks and the pose held when it was made, taken from
        ``current`` or from a newer conditional's solution), as deltas from the points it was
        linearised at. Empty without ``keep_conditionals`` or before the first elimination."""
        out = gtsam.Values()
        points: dict[int, np.ndarray] = {}
        for net, frontal, lms, xy, hold, at in reversed(self._conditionals):
            given = gtsam.VectorValues()
            for k, p0 in zip(lms, xy):
                p = points.get(k)
                if p is None:
                    p = points[k] = np.asarray(current.atPoint2(k))
                given.insert(k, p - p0)
            src = out if out.exists(hold) else current
            given.insert(hold, at.localCoordinates(src.atPose2(hold)))
            out.insert(frontal.retract(net.optimize(given)))
        return out

    def _late_folds(self, b: int, held: gtsam.Values,
                    pose_at: Callable[[np.ndarray], np.ndarray], active: Sequence[int]
                    ) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Conditional folds (:func:`fold_bearings` at the held poses) of the bearings of
        ``active`` landmarks from steps <= ``b`` that are not in the marginal (filed after
        their chunk was eliminated): (id, information (2, 2), information vector (2,))."""
        if not self._late:
            return []
        t, lid, brg = (np.array(c) for c in zip(*self._late))
        sel = (t <= b) & np.isin(lid, np.asarray(active, dtype=np.int64))
        if not sel.any():
            return []
        ids, which = np.unique(lid[sel], return_inverse=True)
        xy = points_at(held, ids)
        info, eta = fold_bearings(pose_at(t[sel]), xy, brg[sel], which,
                                  float(self.header.bearing_sigma_rad),
                                  self.config.bearing_cauchy_k)
        return [(int(i), info[k], eta[k]) for k, i in enumerate(ids.tolist())]

    def reset_folds(self) -> None:
        """Forget every fold and the marginal (a whole-graph solve moves the held poses: the
        next window eliminates every chunk again, at the new values)."""
        self._fold = {}
        self._folded_to = 0
        self._n_marg = 0
        self._marg = gtsam.NonlinearFactorGraph()
        self._conditionals = []
        late, self._late = self._late, []
        for t, lid, b in late:
            self._file(t, lid, b)

    def _fold_upto(self, upto: int, held: gtsam.Values,
                   pose_at: Callable[[np.ndarray], np.ndarray],
                   bearings: tuple[np.ndarray, np.ndarray, np.ndarray],
                   landmark_ids: np.ndarray, active: Sequence[int]) -> None:
        """Fold the bearings of steps ``_folded_to .. upto - 1`` (and, for the active
        landmarks folded too far from their current point or never, all their bearings of
        steps < ``upto``) of landmarks in the graph."""
        owner, lid, brg = bearings
        if not landmark_ids.size or not owner.size:
            return
        refold = [i for i in active if i not in self._fold]
        old = [i for i in active if i in self._fold]
        if old:     # folded farther than refold_m from the current point
            d = points_at(held, old) - np.array([self._fold[i][2] for i in old])
            far = np.hypot(d[:, 0], d[:, 1]) > self.refold_m
            refold = sorted(refold + np.asarray(old)[far].tolist())
        hi = int(np.searchsorted(owner, upto))
        lo = int(np.searchsorted(owner, self._folded_to))
        parts = [np.arange(lo, hi)]
        if refold:
            for i in refold:
                self._fold.pop(i, None)
            r = np.asarray(refold, dtype=np.int64)
            parts.append(np.nonzero(np.isin(lid[:lo], r))[0])
        sel = np.concatenate(parts)
        sel = sel[np.isin(lid[sel], landmark_ids)]
        self._folded_to = max(self._folded_to, upto)
        if not sel.size:
            return
        ids, which = np.unique(lid[sel], return_inverse=True)
        xy = points_at(held, ids)
        ts, at = np.unique(owner[sel], return_inverse=True)
        info, eta = fold_bearings(pose_at(ts)[at], xy, brg[sel], which,
                                  float(self.header.bearing_sigma_rad),
                                  self.config.bearing_cauchy_k)
        for k, i in enumerate(ids.tolist()):
            f = self._fold.get(i)
            if f is None:
                self._fold[i] = [info[k], eta[k], xy[k]]
            else:
                f[0] = f[0] + info[k]
                f[1] = f[1] + eta[k]


def _bayes_net(tree: gtsam.GaussianBayesTree) -> gtsam.GaussianBayesNet:
    """The clique conditionals of ``tree`` as a Bayes net in elimination order (every clique
    after its children), for back-substitution given the variables it was conditioned on."""
    net = gtsam.GaussianBayesNet()
    stack = [(c, False) for c in tree.roots()]
    while stack:
        clique, seen = stack.pop()
        if seen:
            net.push_back(clique.conditional())
            continue
        stack.append((clique, True))
        stack.extend((clique[i], False) for i in range(clique.nrChildren()))
    return net


def fold_bearings(poses: np.ndarray, points: np.ndarray, bearings_rad: np.ndarray,
                  which: np.ndarray, sigma_rad: float, cauchy_k: float | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Bearings from held poses on landmarks, linearised at the landmarks' ``points``, in
    information form: the cost ``sum w (J (l - l0) - r)^2`` of landmark ``k`` is
    ``l^T H_k l - 2 eta_k^T l + const``.

    Parameters
    ----------
    poses : (J, 3) the pose of each bearing; points : (n, 2) the linearisation points;
    bearings_rad : (J,); which : (J,) int, the landmark (0 .. n-1) of each bearing;
    sigma_rad : bearing std. dev.; cauchy_k : Cauchy threshold (whitened) or None
    (iteratively reweighted at ``points``).

    Returns
    -------
    info : (n, 2, 2) ``H = sum w J^T J``; eta : (n, 2) ``H l0 + sum w J^T r``.
    """
    n = len(points)
    pred, d, r2 = bearing_offsets(poses, points[which])
    r2 = np.maximum(r2, 1e-18)
    res = angle_residual(bearings_rad, pred) / sigma_rad
    jx, jy = -d[:, 1] / r2 / sigma_rad, d[:, 0] / r2 / sigma_rad
    w = np.ones_like(res) if cauchy_k is None else 1.0 / (1.0 + (res / cauchy_k) ** 2)
    info = np.empty((n, 2, 2))
    info[:, 0, 0] = np.bincount(which, w * jx * jx, n)
    info[:, 0, 1] = info[:, 1, 0] = np.bincount(which, w * jx * jy, n)
    info[:, 1, 1] = np.bincount(which, w * jy * jy, n)
    grad = np.column_stack([np.bincount(which, w * res * jx, n),
                            np.bincount(which, w * res * jy, n)])
    return info, np.einsum("nij,nj->ni", info, points) + grad
