"""Why Method 1 (``stmds-cs``) maps worse than Method 2 (``stmds-smacof``): one stream's
final map taken apart.

Both methods fuse the same pair distances (the same windows, the same store); Method 1 completes
the missing pairs by shortest paths (DMC-SPL) and runs classical scaling, Method 2 runs SMACOF
on the known pairs, weighted by the inverse variance in the recording presets. For each stream
this prints, on the landmarks ``stmds-cs`` mapped at the end and the known pairs between them:

``cs``
    classical scaling of the fused pairs as ``reconstruct`` does it (equals the method's MPE);
``cs true``
    the same pairs and the same completion, the true distances: the completion's own error;
``cs long true``
    the fused distances with the longer half of the pairs set to the truth;
``smacof 1`` / ``smacof 1/var``
    SMACOF on the same fused pairs from the ``cs`` map, binary or inverse-variance weights
    (the objective alone, then the weights);
``stmds-smacof``
    Method 2's own final map (started from its earlier maps);
``lam2/lam1``, ``|dB|/lam2``
    the true layout's two eigenvalues of the double-centred matrix, and the spectral norm of
    the fused matrix's error against the smaller one (classical scaling's minor axis is lost
    once that nears 1);
``synthetic``
    the median, over 20 draws, of the ratio ``cs`` / ``smacof 1/var`` when the known pairs
    are the true distances plus unbiased Gaussian noise of each pair's stated sd.

All MPEs in cm, rigid alignment with reflection, no scale (as every benchmark scores).

What it showed on the 26 MRCLAM streams of issue 15's generality table (``real``): the known
pairs are 93-100 % of all (``cs true`` <= 1.2 cm: the completion is not the error); setting
the longer half of the pairs to the truth brings ``cs`` to 3-21 cm on 22 of 26 streams
(m6_r5 22.2 -> 3.2, m1_r4 54.6 -> 4.2; on m6att_r1 and m6thin_r5 pairs 0.18 m apart
fused at 1-6 m are the error instead); the layout is long and thin (``lam2/lam1`` 0.07
on MRCLAM6, 0.13 on MRCLAM1) and the fused matrix's error is 0.35-5.4 times its minor
eigenvalue; with unbiased noise of the stated sd ``cs`` is 1.7-6.4x (median 3.4x) the weighted
SMACOF map. Classical scaling fits squared distances unweighted, and the long pairs, whose
error is largest (and stated so), set the map's minor axis: a property of Method 1 on this
geometry, not a fault in the code.

Usage::

    python scripts/diagnose_stmds_cs.py STREAM.jsonl [...] [--preset real]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from bomgraph.evaluate import align  # noqa: E402
from bomgraph.stmds.completion import shortest_path_completion  # noqa: E402
from bomgraph.stmds.mapper import make_stmds_cs, make_stmds_smacof  # noqa: E402
from bomgraph.stmds.mds import classical_scaling, double_centre, smacof  # noqa: E402
from bomgraph.stream import Stream  # noqa: E402
from bomgraph.stream_file import read_stream  # noqa: E402

COLUMNS = ("n", "known %", "cs", "cs true", "cs long true", "smacof 1", "smacof 1/var",
           "stmds-smacof", "lam2/lam1", "|dB|/lam2", "synthetic")


def _mpe_cm(xy: np.ndarray, true_xy: np.ndarray) -> float:
    al = align(xy, true_xy, allow_reflection=True)
    return 100.0 * float(np.mean(np.linalg.norm(al.apply(xy) - true_xy, axis=1)))


def _cs(n: int, first: np.ndarray, second: np.ndarray, dist: np.ndarray) -> np.ndarray:
    return classical_scaling(shortest_path_completion(n, first, second, dist) ** 2)[0]


def _smacof(n: int, first: np.ndarray, second: np.ndarray, dist: np.ndarray,
            weights: np.ndarray, init: np.ndarray) -> np.ndarray:
    return smacof(n, first, second, dist, init=init, weights=weights, max_iter=300,
                  tol=1e-5, relaxation=1.8).points


def final_pairs(stream: Stream, preset: str) -> dict[str, Any]:
    """Run ``stmds-cs`` with ``preset``; its final map, and the known pairs between the
    landmarks it mapped (local indices into ``ids``) with their truth."""
    mapper = make_stmds_cs(stream.header, preset=preset)
    for step in stream.steps:
        mapper.step(step)
    est = mapper.estimate()
    known = mapper._with_open_window()[0].known()
    all_ids = mapper._ids.ids
    local = {int(i): j for j, i in enumerate(est.landmark_ids)}
    a = np.array([local.get(int(i), -1) for i in all_ids[known.first]], np.int64)
    b = np.array([local.get(int(i), -1) for i in all_ids[known.second]], np.int64)
    keep = (a >= 0) & (b >= 0)          # known() holds the pairs with min_count estimates
    truth = dict(zip(stream.truth.landmark_ids.tolist(), stream.truth.landmarks_xy))
    true_xy = np.array([truth[int(i)] for i in est.landmark_ids])
    return {"estimate": est, "ids": est.landmark_ids, "true_xy": true_xy, "first": a[keep],
            "second": b[keep], "distance_m": known.distance_m[keep],
            "variance_m2": known.variance_m2[keep]}


def diagnose(stream: Stream, preset: str = "real", n_draws: int = 20,
             seed: int = 139) -> dict[str, float]:
    """The columns of :data:`COLUMNS` for one stream (see the module docstring)."""
    p = final_pairs(stream, preset)
    true_xy, f, s, d, v = (p["true_xy"], p["first"], p["second"], p["distance_m"],
                           p["variance_m2"])
    n = len(true_xy)
    d_true = np.linalg.norm(true_xy[f] - true_xy[s], axis=1)
    w = 1.0 / np.maximum(v, 1e-300)
    w /= w.mean()
    ones = np.ones(len(d))
    xy_cs = _cs(n, f, s, d)
    long_true = d.copy()
    longer = d_true >= np.median(d_true)
    long_true[longer] = d_true[longer]
    full_true = np.linalg.norm(true_xy[:, None] - true_xy[None], axis=2)
    lam = np.linalg.eigvalsh(double_centre(full_true ** 2))[::-1]
    d_b = double_centre(shortest_path_completion(n, f, s, d) ** 2) - double_centre(full_true ** 2)
    smacof_est = _smacof_final(stream, preset)
    rng = np.random.default_rng(seed)
    ratios = []
    for _ in range(n_draws):
        noisy = np.abs(d_true + rng.normal(0.0, np.sqrt(v)))
        start = _cs(n, f, s, noisy)
        ratios.append(_mpe_cm(start, true_xy)
                      / _mpe_cm(_smacof(n, f, s, noisy, w, start), true_xy))
    return {"n": n, "known %": 100.0 * len(d) / (n * (n - 1) / 2),
            "cs": _mpe_cm(xy_cs, true_xy),
            "cs true": _mpe_cm(_cs(n, f, s, d_true), true_xy),
            "cs long true": _mpe_cm(_cs(n, f, s, long_true), true_xy),
            "smacof 1": _mpe_cm(_smacof(n, f, s, d, ones, xy_cs), true_xy),
            "smacof 1/var": _mpe_cm(_smacof(n, f, s, d, w, xy_cs), true_xy),
            "stmds-smacof": smacof_est,
            "lam2/lam1": float(lam[1] / lam[0]),
            "|dB|/lam2": float(np.linalg.norm(d_b, 2) / lam[1]),
            "synthetic": float(np.median(ratios))}


def _smacof_final(stream: Stream, preset: str) -> float:
    mapper = make_stmds_smacof(stream.header, preset=preset)
    for step in stream.steps:
        mapper.step(step)
    est = mapper.estimate()
    truth = dict(zip(stream.truth.landmark_ids.tolist(), stream.truth.landmarks_xy))
    return _mpe_cm(est.landmarks_xy, np.array([truth[int(i)] for i in est.landmark_ids]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("streams", nargs="+", type=Path, help="stream files with landmark truth")
    ap.add_argument("--preset", default="real", help="preset of both methods (default real)")
    args = ap.parse_args(argv)
    print("| stream | " + " | ".join(COLUMNS) + " |")
    print("|---" * (len(COLUMNS) + 1) + "|")
    for path in args.streams:
        row = diagnose(read_stream(path), args.preset)
        cells = [f"{row[c]:.0f}" if c == "n" else f"{row[c]:.2f}" if "/" in c and "lam" in c
                 else f"{row[c]:.2f}x" if c == "synthetic" else f"{row[c]:.1f}" for c in COLUMNS]
        print(f"| {path.stem} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
