"""bomgraph: bearing-only mapping and SLAM research toolkit.

BOM-STMDS (sequential triangulation + multi-dimensional scaling) next to EKF and GTSAM
baselines, all reading one measurement stream and scored by one Procrustes evaluator.
"""

from importlib import import_module as _import_module
from typing import Any as _Any

from .errors import (BomgraphError, ConfigError, DatasetError, DegenerateGeometryError,
                     EvaluationError, StreamFormatError, UnknownMethodError)

__version__ = "0.1.0"

#: the rest of the API, imported when first used (PEP 562): ``python -m bomgraph`` and the
#: ``bomgraph`` command import this package before their Ctrl-C handler is in place, so it
#: must not take half a second of numpy imports to load.
_LAZY = {**dict.fromkeys(("MapEstimate", "Mapper", "RunResult", "create_mapper", "run"),
                         "mapper"),
         **dict.fromkeys(("Prior", "Step", "Stream", "StreamHeader", "Truth"), "stream"),
         **dict.fromkeys(("read_stream", "write_stream"), "stream_file")}


def __getattr__(name: str) -> _Any:
    if name not in _LAZY:
        # a submodule, as ``import bomgraph`` made them attributes before the API was lazy
        # (README: ``bomgraph.mapper.register_method``, ``bomgraph.stream_file.read_stream``)
        if not name.startswith("_"):
            try:
                return _import_module(f".{name}", __name__)
            except ModuleNotFoundError as exc:
                if exc.name != f"{__name__}.{name}":
                    raise
        raise AttributeError(f"module 'bomgraph' has no attribute {name!r}")
    value = getattr(_import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})

__all__ = ["BomgraphError", "ConfigError", "DatasetError", "DegenerateGeometryError",
           "EvaluationError", "StreamFormatError", "UnknownMethodError", "MapEstimate",
           "Mapper", "RunResult", "create_mapper", "run", "Prior", "Step", "Stream",
           "StreamHeader", "Truth", "read_stream", "write_stream", "__version__"]
