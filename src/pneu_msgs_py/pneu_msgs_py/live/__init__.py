"""Live view without ROS: a run served to the Foxglove app over its WebSocket protocol.

- :class:`~pneu_msgs_py.live.server.LiveServer` -- the ``foxglove-sdk`` server
  (an optional dependency, imported when a server starts) on the bag's topics,
  types and CDR bytes, paced at real time or as fast as possible.
- :class:`~pneu_msgs_py.live.sink.RunSink` -- what a run writes to (a
  ``BagWriter``, a ``LiveServer``), and :class:`~pneu_msgs_py.live.sink.Tee`
  to write to several.
"""

from pneu_msgs_py.live.errors import LiveError
from pneu_msgs_py.live.sink import RunSink, Tee

__all__ = ["PACES", "LiveError", "LiveServer", "RunSink", "Tee"]

PACES = ("realtime", "fast")


def __getattr__(name: str):
    if name == "LiveServer":  # the module imports foxglove only when a server starts
        from pneu_msgs_py.live.server import LiveServer

        return LiveServer
    raise AttributeError(name)
