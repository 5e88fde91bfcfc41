"""A custom hybrid from the public GTSAM helpers: BOM-STMDS map -> seed -> diagnose -> LM.

    python docs/examples/custom_hybrid.py [--steps N]

``baselines.gtsam_tools`` builds the bearing factor graph of a stream (the ``gtsam-batch``
graph), aligns any map into its frame (reflection allowed) as the landmarks' start, names
what is not yet constrained before solving, and reports honestly whether LM converged. The
map is aligned on 3 or more landmarks the graph holds; where the dead-reckoned rays let in
fewer, ``seed_landmarks`` raises: start the poses with ``gt.seed_start`` first
(docs/USAGE.md, "GTSAM helpers").
"""

import argparse

import numpy as np

from baselines import gtsam_tools as gt
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=100, help="steps of the simulated run")
args = parser.parse_args()
stream = simulate(SimConfig(n_steps=args.steps), np.random.default_rng(1))

stmds = run(create_mapper("stmds-smacof", stream.header), stream.steps,
            checkpoint_every=args.steps).final                  # its own, mirrored frame
state = gt.build_graph(stream.header, stream.steps)              # dead-reckoned start
seed = gt.seed_landmarks(state, stmds)                           # aligned into the graph
print(f"seed: {seed.n_common} landmarks aligned, reflected {seed.alignment.reflected}; "
      f"{gt.diagnose(state.graph, state.values).summary()}")
values, report = gt.checked_solve(state.graph, state.values, state.config)
score = score_estimate(state.to_estimate(values, report.as_info()), stream.truth)
print(f"custom hybrid: {score.n_mapped} landmarks, MPE {100 * score.mpe_m:.2f} cm, "
      f"converged {report.converged}")
