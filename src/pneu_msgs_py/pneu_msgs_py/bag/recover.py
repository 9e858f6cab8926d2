"""``pneu recover``: every readable message of a damaged or cut-short bag into a complete, indexed one.

The source is read with the tolerant reader (:class:`~pneu_msgs_py.bag.mcap_file.McapFile`:
summary only if its CRC matches, damaged chunks skipped, a cut end scanned up
to the last complete chunk). Every message of every channel -- pneu's types
and foreign ones alike -- is copied as it was recorded (CDR bytes, log and
publish times, sequence numbers), with each channel's own schema text and
metadata (QoS), into a new bag with chunk and message indexes, statistics and
a summary, which ``ros2 bag info``, ``mcap_ros2`` and ``rosbags`` read. The
metadata records are copied too, with ``pneu.recovered`` added: what was
read, what was lost and why.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pneu_msgs_py import __version__
from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.chunks import Batch, merge_same_channel
from pneu_msgs_py.bag.container import McapContainer
from pneu_msgs_py.bag.errors import EmptyBagError
from pneu_msgs_py.bag.mcap_file import McapFile, walk_offsets
from pneu_msgs_py.bag.reader import bag_files
from pneu_msgs_py.bag.rosbag2_meta import rosbag2_metadata

__all__ = ["RECOVERED_METADATA", "RecoveryReport", "recover"]

RECOVERED_METADATA = "pneu.recovered"
_HDR = R.MESSAGE_HEADER_SIZE


@dataclass
class RecoveryReport:
    """What :func:`recover` read and what it could not."""

    source: str
    out: str
    messages: int = 0
    topics: dict[str, int] = field(default_factory=dict)
    lost: int = 0  # counted messages in damaged chunks
    lost_unknown: bool = False  # some loss could not be counted (a cut end, a damaged index)
    damaged_chunks: int = 0
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)

    def line(self) -> str:
        lost = f"{self.lost} message(s) lost" + (
            " (and an uncounted number in the cut or unreadable part)" if self.lost_unknown else ""
        )
        return (
            f"recovered {self.messages} messages on {len(self.topics)} topics from {self.source} "
            f"into {self.out}; {lost}"
            + (f"; {self.damaged_chunks} damaged chunk(s) skipped" if self.damaged_chunks else "")
            + ("; the source was cut short" if self.truncated else "")
        )


def _channel_rows(data: bytes, offs: np.ndarray) -> list[np.ndarray]:
    """The message records at ``offs`` as ``(n, 31 + size)`` byte rows, one array per size."""
    buf = np.frombuffer(data, dtype=np.uint8)
    offs = offs[(offs >= 0) & (offs + _HDR <= len(buf))]
    if not len(offs):
        return []
    hv = buf[offs[:, None] + np.arange(_HDR)].view(R.MESSAGE_RECORD_DTYPE)[:, 0]
    sizes = hv["length"].astype(np.int64) - 22
    ok = (hv["op"] == R.Op.MESSAGE) & (sizes >= 0) & (offs + _HDR + sizes <= len(buf))
    out = []
    for size in np.unique(sizes[ok]).tolist():
        o = offs[ok & (sizes == size)]
        out.append(buf[o[:, None] + np.arange(_HDR + size)])
    return out


def _chunk_batches(chunk, f: McapFile, container: McapContainer, rep: RecoveryReport):
    """The chunk's messages as batches of the new file's channels (records copied as they are)."""
    offsets = chunk.offsets if chunk.offsets is not None else walk_offsets(chunk.data)
    if any(cid not in f.channels for cid in offsets):
        f.definitions_in(chunk.data)
    batches: list[Batch] = []
    read: dict[int, int] = {}
    for cid, offs in offsets.items():
        info = f.channels.get(cid)
        if info is None:
            rep.lost_unknown = True  # messages of a channel whose definition was lost
            continue
        sch = f.schemas.get(info.schema_id)
        ch = container.channel(
            info.topic,
            sch.name if sch else "unknown/msg/Unknown",
            schema_text=sch.data if sch else b"",
            channel_metadata=info.metadata,
        )
        parts = []
        for rows in _channel_rows(chunk.data, offs):
            rows[:, 9:11] = np.frombuffer(np.uint16(ch.id).tobytes(), dtype=np.uint8)
            lt = rows[:, 15:23].copy().view("<i8")[:, 0]  # log_time (MESSAGE_RECORD_DTYPE)
            parts.append(Batch(ch, lt, rows=rows))
            ch.count += len(rows)
            read[cid] = read.get(cid, 0) + len(rows)
        if len(parts) > 1:  # one channel in several record sizes: one time-ordered batch
            parts = [merge_same_channel(parts)]
        batches.extend(parts)
        rep.topics[info.topic] = rep.topics.get(info.topic, 0) + read.get(cid, 0)
    return batches, read


def recover(
    source: str | os.PathLike, out: str | os.PathLike, *, partial: str | os.PathLike | None = None
) -> RecoveryReport:
    """Copy every readable message of ``source`` into the complete bag ``out`` (see the module).

    ``out`` is written as ``partial`` (default ``out.partial``; another name when that is
    ``source``: recovering ``run.mcap.partial`` onto ``run.mcap``) and renamed when complete. Raises
    :class:`EmptyBagError` (nothing readable, ``out`` not written) or another
    :class:`~pneu_msgs_py.bag.errors.BagError` for a file that is not a bag.
    """
    files, warn = bag_files(source)
    out = Path(out)
    rep = RecoveryReport(str(source), str(out), warnings=list(warn))
    container = McapContainer(
        out,
        f"pneu_msgs_py {__version__} (pneu recover)",
        "zstd",
        "lockstep",
        partial=Path(partial) if partial is not None else None,
    )
    metadata: dict[str, dict[str, str]] = {}
    try:
        for path in files:
            with McapFile(path) as f:
                read: dict[int, int] = {}
                for chunk in f.iter_chunks():
                    if chunk.problem:
                        rep.damaged_chunks += 1
                        if chunk.lost is None:
                            rep.lost_unknown = True
                        else:
                            rep.lost += sum(chunk.lost.values())
                        rep.warnings.append(f"{path}: {chunk.problem}: chunk skipped")
                        continue
                    batches, got = _chunk_batches(chunk, f, container, rep)
                    for cid, n in got.items():
                        read[cid] = read.get(cid, 0) + n
                    if batches:
                        container.write_chunk(batches)
                for name, md in f.metadata.items():
                    metadata.setdefault(name, {}).update(md)
                rep.warnings.extend(f"{path}: {w}" for w in f.warnings)
                rep.truncated |= f.truncated
                if f.truncated:
                    rep.lost_unknown = True
                if f.message_counts and not f.truncated:
                    missing = sum(max(0, n - read.get(c, 0)) for c, n in f.message_counts.items())
                    if missing > rep.lost:
                        rep.lost = missing  # the statistics count what the indexes could not
        rep.messages = sum(rep.topics.values())
        if rep.messages == 0:
            raise EmptyBagError(source, "no readable message to recover")
        metadata.pop("rosbag2", None)  # rewritten for the new file at finish
        for name, md in metadata.items():
            container.add_metadata(name, md)
        container.add_metadata(
            RECOVERED_METADATA,
            {
                "source": str(source),
                "messages": str(rep.messages),
                "lost": str(rep.lost),
                "lost_uncounted": "true" if rep.lost_unknown else "false",
                "damaged_chunks": str(rep.damaged_chunks),
                "source_truncated": "true" if rep.truncated else "false",
                "warnings": " | ".join(rep.warnings)[:4000],
            },
        )
        channels = list(container.channels.values())
        container.finish(
            rosbag2_metadata(channels, out.name, container.t_start, container.t_end, "pneu recover")
        )
    except BaseException:
        container.close()
        container.partial_path.unlink(missing_ok=True)
        raise
    container.close()
    return rep
