"""MCAP bags of pneu runs: writer, reader, schemas, bulk CDR, errors, benchmarks."""

from pneu_msgs_py.bag.errors import (
    BagError,
    BagWriteError,
    EmptyBagError,
    MissingTopicError,
    NotMcapError,
    NotRos2Error,
    TruncatedBagError,
    TruncatedBagWarning,
    UnknownSchemaError,
)
from pneu_msgs_py.bag.writer import BagWriter, DiagStatus

__all__ = [
    "BagWriter",
    "DiagStatus",
    "BagError",
    "BagWriteError",
    "NotMcapError",
    "NotRos2Error",
    "TruncatedBagError",
    "TruncatedBagWarning",
    "MissingTopicError",
    "UnknownSchemaError",
    "EmptyBagError",
]
