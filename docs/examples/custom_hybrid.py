"""A custom hybrid: GTSAM's bearing factor graph (the ``gtsam-batch`` graph and solver)
seeded with a BOM-STMDS map of your choice, from the public pieces of ``baselines``.

    python docs/examples/custom_hybrid.py [--steps N]

``HybridMapper`` aligns the seed map into the odometry frame (reflection allowed), resects
every pose against it (``baselines.resection.resect_trajectory``) and runs Levenberg-Marquardt
on the same graph as ``gtsam-batch`` (``baselines.factor_graph.BatchState``). Here the seed is
BOM-STMDS with windowed triangulation (preset ``"window"``) instead of the default.
"""

import argparse

import numpy as np

from baselines.factor_graph import BatchMapper
from baselines.hybrid import HybridConfig, HybridMapper
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stmds.mapper import make_stmds_smacof

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=100, help="steps of the simulated run")
args = parser.parse_args()

stream = simulate(SimConfig(n_steps=args.steps), np.random.default_rng(1))
header, truth = stream.header, stream.truth

mappers = {
    "gtsam-batch (dead-reckoned start)": BatchMapper(header),
    "hybrid, window seed": HybridMapper(
        header, seed_mapper=make_stmds_smacof(header, preset="window"),
        config=HybridConfig.preset("paper", align_steps=30)),
}
for name, mapper in mappers.items():
    result = run(mapper, stream.steps, checkpoint_every=args.steps)
    score = score_estimate(result.final, truth)
    info = result.final.info
    print(f"{name:36s} {score.n_mapped:3d} landmarks, MPE {100 * score.mpe_m:6.2f} cm, "
          f"converged {info.get('converged')}")
