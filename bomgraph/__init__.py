"""bomgraph: bearing-only mapping and SLAM research toolkit.

BOM-STMDS (sequential triangulation + multi-dimensional scaling) next to EKF and GTSAM
baselines, all reading one measurement stream and scored by one Procrustes evaluator.
"""

from .errors import (BomgraphError, ConfigError, DatasetError, DegenerateGeometryError,
                     EvaluationError, StreamFormatError, UnknownMethodError)
from .mapper import MapEstimate, Mapper, RunResult, create_mapper, run
from .stream import Prior, Step, Stream, StreamHeader, Truth
from .stream_file import read_stream, write_stream

__version__ = "0.1.0"

__all__ = ["BomgraphError", "ConfigError", "DatasetError", "DegenerateGeometryError",
           "EvaluationError", "StreamFormatError", "UnknownMethodError", "MapEstimate",
           "Mapper", "RunResult", "create_mapper", "run", "Prior", "Step", "Stream",
           "StreamHeader", "Truth", "read_stream", "write_stream", "__version__"]
