"""Where the tests find the shared recordings (MRCLAM, the bearing-only g2o pair, Victoria
Park), which are never in the repository: ``$BOMGRAPH_DATA``, else ``../shared/data`` beside
the checkout (as the scripts look). A test that needs them and does not find them says where
it looked and how to give them (``missing``)."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: An empty ``BOMGRAPH_DATA`` counts as unset (``Path("")`` would be the working folder).
DATA = Path(os.environ.get("BOMGRAPH_DATA") or ROOT.parent / "shared" / "data")


def missing(*parts: str) -> str:
    """Why a test that needs ``DATA/parts`` cannot run: where it looked, and what to set."""
    return (f"no {DATA.joinpath(*parts)}: the shared recordings are looked for in "
            f"$BOMGRAPH_DATA, else in ../shared/data beside the checkout; set BOMGRAPH_DATA "
            f"to their folder")
