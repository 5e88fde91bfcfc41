"""Importers that turn real recordings into a bomgraph Stream (issue 7).

- :func:`~bomgraph.datasets.mrclam.import_mrclam`: UTIAS MRCLAM, one robot, keyframed and
  calibrated against its ground truth.
- :func:`~bomgraph.datasets.g2o.import_g2o`: bearing-only g2o files (``EDGE_SE2``,
  ``EDGE_BEARING_SE2_XY``), optional ground-truth file.
- :func:`~bomgraph.datasets.victoria.import_victoria`: GTSAM's Victoria Park text file.

Each importer declares the files it reads, role -> file (:func:`mrclam_inputs`,
:func:`g2o_inputs`, :func:`victoria_inputs`): what a recording's cache key hashes
(:class:`bomgraph.sources.DatasetSource`).

A malformed input line raises :class:`~bomgraph.errors.DatasetError` naming the file, the line
and the field.
"""

from .g2o import g2o_inputs, import_g2o
from .mrclam import KeyframeConfig, import_mrclam
from .mrclam_files import mrclam_inputs
from .victoria import import_victoria, victoria_inputs

__all__ = ["import_g2o", "import_mrclam", "import_victoria", "KeyframeConfig", "g2o_inputs",
           "mrclam_inputs", "victoria_inputs"]
