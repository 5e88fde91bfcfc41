"""BOM-STMDS: bearing-only mapping by sequential triangulation and multi-dimensional scaling.

One module per step of the paper's section III:

* :mod:`.config` -- the options and their named presets;
* :mod:`.triangulation` -- sequential triangulation, instantaneous pair distances and their
  first-order variances (III-B, eq. 1-2), gates for degenerate geometry;
* :mod:`.window`, :mod:`.bundle` -- triangulation over windows of poses (two rays, all rays,
  a local bundle adjustment);
* :mod:`.distances` -- inverse-variance fusion of the pair distances and priors (III-C,
  eq. 3-5), with the literal rule and the corrected ones;
* :mod:`.completion` -- DMC-SPL, shortest paths over the graph of known pairs (III-D.1);
* :mod:`.mds` -- classical scaling and weighted SMACOF (III-D, III-D.2, eq. 6);
* :mod:`.reconstruct` -- known pairs to coordinates, Methods 1 and 2 (III-D);
* :mod:`.localisation` -- the last p robot poses, their distances and headings (III-E);
* :mod:`.mapper` -- the online schedule (Algorithm 1) as Mappers
  (registered as ``stmds-cs``, ``stmds-smacof``, ``stmds-cs-loc``, ``stmds-smacof-loc``).
"""

from .config import StmdsConfig
from .mapper import StmdsMapper

__all__ = ["StmdsConfig", "StmdsMapper"]
