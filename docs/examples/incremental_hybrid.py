"""An incremental hybrid: iSAM2 whose pending landmarks enter at their BOM-STMDS position.

Every 10 steps of a simulated run: landmarks whose rays intersect enter as in gtsam-isam2,
pending ones with 3 bearings at the BOM-STMDS map's position (aligned onto iSAM2's); one iSAM2
update with gtsam-isam2's settings (GTSAM's defaults: 7.8 cm at --steps 100, not 1.8 cm).
"""

import argparse

import gtsam
import numpy as np

from baselines import gtsam_tools as gt
from bomgraph.errors import TooFewLandmarksError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import create_mapper, run
from bomgraph.sim import SimConfig, simulate

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=300, help="steps of the simulated run")
args = parser.parse_args()
stream = simulate(SimConfig(n_steps=args.steps), np.random.default_rng(7))
config = gt.Isam2Config()                                  # gtsam-isam2's paper preset
problem = gt.BearingGraph(stream.header, config, np.zeros(3))
isam, factors = gtsam.ISAM2(gt.isam2_params(config)), gtsam.NonlinearFactorGraph()
stmds = create_mapper("stmds-smacof", stream.header)
new, poses, est, n_seeded = gtsam.Values(), np.zeros((0, 3)), gtsam.Values(), 0
for step in stream.steps:
    stmds.step(step)
    problem.add_step(step)
    prev = poses[-1] if step.t else None
    poses = np.vstack([poses, problem.predict_pose(step.t, prev)])
    gt.insert_pose(new, step.t, poses[-1], prev)
    if step.t % 10 and step.t < len(stream.steps) - 1:
        continue
    problem.admit(lambda ts: poses[ts])                    # rays that intersect, as gtsam-isam2
    held = [i for i in problem.landmark_ids if est.exists(gt.landmark_key(i))]
    try:                                                   # the BOM-STMDS map onto iSAM2's
        where = gt.align_map(stmds.estimate(), held, gt.landmarks_from_values(est, held))
        seed = {i: xy for i, xy in where.as_dict().items() if problem.pending().get(i, 0) >= 3}
    except TooFewLandmarksError:                           # fewer than 3 in common yet
        seed = {}
    for lid, xy in seed.items():                           # any parallax: the map has them
        problem.enter(lid, xy)
    n_seeded += len(seed)
    batch = problem.take_new()
    batch.core.push_back(batch.landmark)
    new.insert(batch.landmark_values)
    isam.update(batch.core, new)
    for _ in range(config.checkpoint_updates):
        isam.update()
    factors.push_back(batch.core)
    new, est = gtsam.Values(), isam.calculateEstimate()
    poses = gt.poses_from_values(est, np.arange(step.t + 1))
hybrid = gt.estimate_from_values(problem, est, factors)
ref = run(create_mapper("gtsam-isam2", stream.header), stream.steps, checkpoint_every=10).final
for name, estimate in ((f"incremental hybrid ({n_seeded} seeded)", hybrid), ("gtsam-isam2", ref)):
    score = score_estimate(estimate, stream.truth)
    print(f"{name}: {score.n_mapped} landmarks, MPE {100 * score.mpe_m:.2f} cm")
