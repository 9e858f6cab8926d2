"""MCAP bags of pneu runs: writer, reader, schemas, bulk CDR, errors, benchmarks.

Why the chunks are pneu's own, while ``mcap``, ``mcap-ros2-support`` and
``rosbags`` are requirements. Measured with ``python -m pneu_msgs_py.bench.bag
--writers``: a 20 s both-axes 1 kHz run with the 10 topics of ``pneu run``
(180,020 messages), 1 MiB zstd chunks, best of 3; 2-core AMD EPYC VM,
CPython 3.11.7, mcap 1.6.0, mcap-ros2-support 0.6.0. Figures from the
quietest run; five more runs on the shared VM (load 8-10) kept the ratios.

- **Writing.** The library's only way into a chunk is ``mcap.Writer.add_message``,
  one Python record object per message, about 6 µs each. :class:`BagWriter`
  builds a chunk's message records and indexes by the thousand with numpy
  (:mod:`.chunks`, :mod:`.cdr`): 16 µs per 1 kHz cycle of 9 messages, close
  included, against 58 µs for the same bulk CDR and chunk cuts through
  ``mcap.Writer`` (``bench.bag._LibraryContainer``; 3.4-6.9x slower over the
  runs) and 175 µs for ``mcap_ros2``'s Writer (a dict encoded per message).
  End to end, the in-process closed loop (both axes, ESO-SMC, 20 s) ran at
  10.5x real time logged by pneu's container and 5.3x through
  ``mcap.Writer`` (17.7x unlogged). Already-CDR messages one at a time (the
  ROS logger, :meth:`BagWriter.write_serialized`): 2.2-2.5x faster than
  ``mcap.Writer``. zstd is level 1 (``mcap.Writer`` fixes level 3: 10-45 %
  slower here, 1.5 % larger files).
- **Reading.** ``read_run`` decodes whole chunks from their message indexes
  with numpy: 1.16 M messages/s into arrays, against 134 k/s for ``mcap``'s
  reader handing out the raw records (nothing decoded), 42 k/s for
  ``mcap_ros2`` and 65 k/s for ``rosbags``, decoded (read_run 6-9.5x ``mcap`` over the runs).
- **Damage.** ``mcap``'s readers cannot skip a damaged chunk or read a cut
  file (``test/msgs/bag/test_corruption.py``, a real bag with a flipped
  byte): with CRCs checked, ``make_reader(...).iter_messages`` and
  ``StreamReader.records`` raise ``CRCValidationError`` at the damaged chunk
  and end there; without, they hand out its wrong bytes. A cut file (no
  footer) and a damaged summary (the library does not check its CRC) end
  ``make_reader`` with ``EndOfFile``; a record with an impossible length
  ends ``StreamReader`` (``RecordLengthLimitExceeded``), with no resync. So
  the tolerant reader (:mod:`.mcap_file`: the summary trusted only if its
  CRC matches, damaged chunks skipped and counted, a resync to the next
  intact chunk) and ``pneu recover`` (:mod:`.recover`) stay.

What is the library's: every record but message records and message indexes
is written and parsed by ``mcap.records`` (:mod:`.mcap_records`), and the
test suite reads pneu's bags with ``mcap``, ``mcap_ros2`` and ``rosbags``.
"""

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
