"""``python -m bomgraph``: the ``bomgraph`` command."""

import sys

try:
    from .cli import program
except KeyboardInterrupt:  # Ctrl-C while the command is imported, before its handler is in
    print("bomgraph: interrupted" + ("; rerun to resume" if sys.argv[1:2] == ["compare"]
                                     else ""), file=sys.stderr)
    exec("None")  # as bomgraph.cli_signals.forget_unhandled_interrupt: exit 130, not by SIGINT
    sys.exit(130)

sys.exit(program())
