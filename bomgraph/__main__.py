"""``python -m bomgraph``: the ``bomgraph`` command."""

import sys

from .cli import main

sys.exit(main())
