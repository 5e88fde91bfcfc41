"""Your recording through every method: each registered mapper on one stream file, scored
against the stream's truth when it has one.

    python docs/examples/every_method.py [STREAM.jsonl] [--steps N] [--preset real]

Without a stream, a run of the paper's simulated world is made (``--steps``, default 120).
``--preset NAME`` runs each method that has that preset with it (``real``: the settings for
recordings; with the paper's defaults BOM-STMDS and ``ekf`` map almost nothing on MRCLAM).
"""

import argparse

import numpy as np

from bomgraph.errors import BomgraphError
from bomgraph.evaluate import score_estimate
from bomgraph.mapper import available_methods, create_mapper, method_config_class, run
from bomgraph.sim import SimConfig, simulate
from bomgraph.stream_file import read_stream

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("stream", nargs="?", help="a stream file (default: simulate one)")
parser.add_argument("--steps", type=int, default=120, help="steps of the simulated run")
parser.add_argument("--preset", help="each method's preset of this name, where it has one")
args = parser.parse_args()

if args.stream:
    stream = read_stream(args.stream)
else:
    stream = simulate(SimConfig(n_steps=args.steps), np.random.default_rng(0))

print(f"{'method':22s} {'mapped':>6s} {'MPE cm':>8s} {'s':>6s}")
for info in available_methods():
    if info.needs_truth:  # the oracle is a benchmark bound, not a method for real data
        continue
    presets = getattr(method_config_class(info.name), "PRESETS", {})
    options = {"preset": args.preset} if args.preset in presets else {}
    try:
        mapper = create_mapper(info.name, stream.header, **options)
        result = run(mapper, stream.steps, checkpoint_every=50, method=info.name)
    except BomgraphError as exc:
        print(f"{info.name:22s} failed: {exc}")
        continue
    mpe = "-"
    if stream.truth is not None and len(result.final) >= 3:
        mpe = f"{100 * score_estimate(result.final, stream.truth).mpe_m:.2f}"
    name = info.name + (f"@{args.preset}" if options else "")
    print(f"{name:22s} {len(result.final):6d} {mpe:>8s} {result.total_s:6.2f}")
