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
from pneu_msgs_py.bag.chunks import Batch
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


def _records(chunk) -> list[tuple[int, int, int, int, bytes]]:
    """(channel id, sequence, log time, publish time, data) of every message record of a chunk."""
    data = chunk.data
    offsets = chunk.offsets if chunk.offsets is not None else walk_offsets(data)
    buf = np.frombuffer(data, dtype=np.uint8)
    out = []
    for offs in offsets.values():
        for o in offs.tolist():
            if o < 0 or o + _HDR > len(buf):
                continue
            rec = buf[o : o + _HDR].view(R.MESSAGE_RECORD_DTYPE)[0]
            size = int(rec["length"]) - 22
            if rec["op"] != R.Op.MESSAGE or size < 0 or o + _HDR + size > len(buf):
                continue
            out.append(
                (
                    int(rec["channel_id"]),
                    int(rec["sequence"]),
                    int(rec["log_time"]),
                    int(rec["publish_time"]),
                    data[o + _HDR : o + _HDR + size],
                )
            )
    return out


def recover(source: str | os.PathLike, out: str | os.PathLike) -> RecoveryReport:
    """Copy every readable message of ``source`` into the complete bag ``out`` (see the module).

    ``out`` is written as ``out.partial`` and renamed when complete. Raises
    :class:`EmptyBagError` (nothing readable, ``out`` not written) or another
    :class:`~pneu_msgs_py.bag.errors.BagError` for a file that is not a bag.
    """
    files, warn = bag_files(source)
    out = Path(out)
    rep = RecoveryReport(str(source), str(out), warnings=list(warn))
    container = McapContainer(out, f"pneu_msgs_py {__version__} (pneu recover)", "zstd", "lockstep")
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
                    recs = _records(chunk)
                    if any(cid not in f.channels for cid, *_ in recs):
                        f.definitions_in(chunk.data)
                    batches: dict[int, tuple[object, list[int], list[bytes]]] = {}
                    for cid, seq, lt, pt, data in recs:
                        ch_info = f.channels.get(cid)
                        if ch_info is None:
                            rep.lost_unknown = True
                            continue
                        sch = f.schemas.get(ch_info.schema_id)
                        name = sch.name if sch else "unknown/msg/Unknown"
                        ch = container.channel(
                            ch_info.topic,
                            name,
                            schema_text=sch.data if sch else b"",
                            channel_metadata=ch_info.metadata,
                        )
                        b = batches.setdefault(ch.id, (ch, [], []))
                        b[1].append(lt)
                        b[2].append(R.message(ch.id, seq & 0xFFFFFFFF, lt, pt, data))
                        read[cid] = read.get(cid, 0) + 1
                    out_batches = []
                    for ch, lts, blobs in batches.values():
                        ch.count += len(blobs)
                        rep.topics[ch.topic] = rep.topics.get(ch.topic, 0) + len(blobs)
                        out_batches.append(Batch(ch, np.array(lts, dtype=np.int64), records=blobs))
                    if out_batches:
                        container.write_chunk(out_batches)
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
