"""``gtsam-batch`` in the scale world of ``scripts/bench_scale.py`` (issue 14 item 5): where its
CPU goes and how far its final map is from the whole-graph optimum.

Runs one world of N landmarks (the paper's density, ``6 N`` steps, estimate at the end only, as
``bench_scale.py``), timing the whole-graph and the fixed-lag window LM solves separately
(``time.process_time``, single-threaded BLAS), then checks the final values against the
whole graph: Gauss-Newton (6 iterations) and Levenberg-Marquardt from them, the cost before
and after, and the RMS distance of the mapped landmarks between the two. Also times the paper run (300 steps) in
the same process as the reference for the machine's speed.

Usage: ``python scripts/bench_batch_scale.py [--n 1000] [--seed 11] [--opt full_growth=1.5 ...]``.
"""

from __future__ import annotations

import argparse
import math
import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def main() -> None:
    from dataclasses import replace

    import gtsam
    import numpy as np

    import baselines.factor_graph as fg
    from baselines.bearing_graph import landmarks_from_values
    from bomgraph.evaluate import score_estimate
    from bomgraph.mapper import create_mapper
    from bomgraph.sim import SimConfig, simulate

    import bench_scale

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=11, help="the world's seed (bench_scale: 11)")
    ap.add_argument("--opt", nargs="*", default=[], help="FactorGraphConfig field=value")
    ap.add_argument("--no-check", action="store_true", help="skip the whole-graph check")
    args = ap.parse_args()
    opts = {k: eval(v) for k, v in (o.split("=", 1) for o in args.opt)}  # noqa: S307
    n = args.n
    side = bench_scale.PAPER_SIDE_M * math.sqrt(n / bench_scale.PAPER_N)
    stream = simulate(SimConfig(arena_m=side, n_landmarks=n,
                                n_steps=bench_scale.PAPER_STEPS * n // bench_scale.PAPER_N),
                      np.random.default_rng(args.seed))
    mapper = create_mapper("gtsam-batch", stream.header, **opts)
    whole: list[tuple[int, float, int, tuple]] = []
    window = [0.0, 0, 0]
    back = [0.0, 0]       # finish()'s solve with the near bearings back in
    solve_lm = fg.solve_lm

    def timed(graph, *a, **k):
        c = time.process_time()
        out = solve_lm(graph, *a, **k)
        d = time.process_time() - c
        if k.get("looks_off") is fg.never_off and graph is mapper.state.graph:
            back[0] += d
            back[1] += out[1].iterations
        elif k.get("looks_off") is fg.never_off:
            window[0] += d
            window[1] += 1
            window[2] += out[1].iterations
        else:
            whole.append((mapper.state.problem.n_steps, d, out[1].iterations, out[1].passes))
        return out

    fg.solve_lm = timed
    c0 = time.process_time()
    for s in stream.steps:
        mapper.step(s)
    c1 = time.process_time()
    mapper.finish()         # as bomgraph.mapper.run after the last step
    est = mapper.estimate()
    cpu = time.process_time() - c0
    finish_s = time.process_time() - c1
    fg.solve_lm = solve_lm
    mpe = score_estimate(est, stream.truth).mpe_m
    w_s = sum(w[1] for w in whole)
    print(f"N={n} seed {args.seed} {opts}: CPU {cpu:.1f} s, MPE {100 * mpe:.3f} cm, {len(est)} mapped")
    print(f"  finish() and the final estimate {finish_s:.1f} s; near bearings put back: "
          f"{est.info.get('near_bearings_back')} (that solve {back[0]:.1f} s, {back[1]} "
          f"iterations); final cost {est.info.get('cost')}")
    print(f"  whole-graph solves {w_s:.1f} s for {len(whole)} ({sum(w[2] for w in whole)} LM "
          f"iterations), {sum(w[1] for w in whole if w[0] > 500):.1f} s past 500 steps; "
          f"window solves {window[0]:.1f} s for {window[1]} ({window[2]} iterations)")
    for t, d, it, passes in whole:
        if t > 500 or "huber" in passes:
            print(f"    whole at {t}: {d:.2f} s, {it} iterations, {'+'.join(passes)}")
    if not args.no_check:
        state = mapper.state
        ids = est.landmark_ids
        # the graph the final values solve (every bearing once finish() has put the near
        # ones back; else without them)
        graph = state.solved_graph
        cost = graph.error(state.values)
        gn = gtsam.GaussNewtonParams()
        gn.setMaxIterations(6)
        lm = gtsam.LevenbergMarquardtParams()
        lm.setRelativeErrorTol(1e-7)
        lm.setMaxIterations(50)
        for name, opt in (("Gauss-Newton (6 iterations)",
                           gtsam.GaussNewtonOptimizer(graph, state.values, gn)),
                          ("Levenberg-Marquardt (rel. tol 1e-7)",
                           gtsam.LevenbergMarquardtOptimizer(graph, state.values, lm))):
            best = opt.optimize()
            d = landmarks_from_values(best, ids) - est.landmarks_xy
            opt_est = replace(est, landmarks_xy=landmarks_from_values(best, ids))
            print(f"  whole-graph check, {name}: cost {cost:.3f} -> "
                  f"{graph.error(best):.3f}, landmarks "
                  f"{1e3 * math.sqrt(np.mean(np.sum(d * d, axis=1))):.3f} mm RMS from its "
                  f"result, MPE of its result "
                  f"{100 * score_estimate(opt_est, stream.truth).mpe_m:.3f} cm", flush=True)
    print(f"  reference paper run {bench_scale._paper_run_cpu_s('gtsam-batch'):.2f} s")


if __name__ == "__main__":
    main()
