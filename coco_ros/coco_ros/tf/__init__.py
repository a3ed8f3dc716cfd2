"""The TF bridge: the transformation graph <-> /tf and /tf_static (see :mod:`.bridge`)."""

from .ingest import TFIngest
from .selection import TFSelection, parse_pair

__all__ = ["TFIngest", "TFSelection", "parse_pair"]
