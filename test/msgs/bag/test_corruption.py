"""Real corruption: bytes flipped in a real bag, read back by pneu and by independent readers.

A damaged chunk is skipped with a warning counting the messages lost (from its
message index, independently known here from the ``mcap`` library's summary);
everything else reads exactly as written. ``recover`` turns any readable
damaged or cut bag into one that ``mcap_ros2`` and ``rosbags`` read completely.
Random flips anywhere never give anything but a result or one ``BagError`` line.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap_ros2.reader import read_ros2_messages
from pneu_msgs_py.bag import BagError, BagWriter
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.bag.recover import recover
from pneu_msgs_py.contract.samples import SensorSample

N = 2500
P1 = "/pneu/pressure/cylinder_1"


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("bags") / "run.mcap"
    with BagWriter(p, chunk_size=24 * 1024, metadata={"pneu.run": {"seed": "3"}}) as w:
        for k in range(N):
            w.write_sample(SensorSample(k, k * 1_000_000, 1e5 + k, 2e5, 3e5, 1e-5 * k, 0.0, 0.0, k))
            w.write_command("linear", k * 1_000_000, 5.0 + 1e-4 * k)
    return p


def chunks_of(path: Path):
    """(start, length, messages per channel id) of every chunk, from the mcap library."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    out = []
    for ci in summary.chunk_indexes:
        counts = {}
        with open(path, "rb") as f:
            for cid, off in ci.message_index_offsets.items():
                f.seek(off + 1 + 8 + 2)
                counts[cid] = int.from_bytes(f.read(4), "little") // 16
        out.append((ci.chunk_start_offset, ci.chunk_length, counts))
    return out


def flipped(src: Path, dst: Path, *positions: int) -> Path:
    b = bytearray(src.read_bytes())
    for pos in positions:
        b[pos] ^= 0x5A
    dst.write_bytes(bytes(b))
    return dst


def independent_count(path: Path, decode: bool = True) -> int:
    """Messages read by rosbags and by mcap (decoding each with mcap_ros2 if ``decode``)."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as r:
        n1 = sum(1 for _ in r.messages())
    if decode:
        n2 = sum(1 for _ in read_ros2_messages(str(path)))
    else:
        with open(path, "rb") as f:
            n2 = sum(1 for _ in make_reader(f).iter_messages())
    assert n1 == n2
    return n1


def test_a_damaged_chunk_is_skipped_and_its_messages_counted(bag, tmp_path):
    chunks = chunks_of(bag)
    assert len(chunks) >= 5
    start, length, counts = chunks[2]
    lost = sum(counts.values())
    bad = flipped(bag, tmp_path / "bad.mcap", start + length // 2)  # inside the compressed data
    with pytest.warns(UserWarning, match=rf"chunk skipped, {lost} messages lost"):
        d = read_run(bad)
    whole = read_run(bag)
    assert d.message_count == whole.message_count - lost
    # what is left is exactly what was written (the damaged chunk's cycles are missing)
    keep = np.isin(whole[P1].stamp_ns, d[P1].stamp_ns)
    assert keep.sum() == len(d[P1]) < N
    np.testing.assert_array_equal(d[P1]["fluid_pressure"], whole[P1]["fluid_pressure"][keep])
    # recover: a complete bag of the rest, read completely by independent readers
    fixed = tmp_path / "fixed.mcap"
    rep = recover(bad, fixed)
    assert rep.lost == lost and rep.damaged_chunks == 1 and not rep.lost_unknown
    assert rep.messages == d.message_count == independent_count(fixed)
    rec = read_run(fixed).metadata["pneu.recovered"]
    assert rec["lost"] == str(lost) and rec["damaged_chunks"] == "1"


def test_the_mcap_library_cannot_read_past_damage_pneu_can(bag, tmp_path):
    """Why pneu keeps its tolerant reader (see pneu_msgs_py.bag): mcap's readers stop at a
    damaged chunk (its CRC checked) and at a cut end; they do not skip and read on."""
    chunks = chunks_of(bag)
    start, length, counts = chunks[2]
    bad = flipped(bag, tmp_path / "bad.mcap", start + length // 2)
    with open(bad, "rb") as f, pytest.raises(CRCValidationError):
        for _ in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False):
            pass
    before = sum(sum(c.values()) for _, _, c in chunks[:2])
    with open(bad, "rb") as f:
        records = StreamReader(f, validate_crcs=True).records
        got = 0
        with pytest.raises(CRCValidationError):
            for rec in records:
                got += isinstance(rec, Message)
        assert got == before  # the chunks before the damaged one, then the reader is done
        assert next(records, None) is None
    with pytest.warns(UserWarning, match="chunk skipped"):
        assert read_run(bad).message_count == read_run(bag).message_count - sum(counts.values())
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    with open(cut, "rb") as f, pytest.raises(McapError):
        next(make_reader(f).iter_messages())
    with pytest.warns(UserWarning, match="truncated"):
        assert read_run(cut).message_count > 0


def test_a_damaged_summary_is_not_trusted_and_nothing_is_lost(bag, tmp_path):
    size = bag.stat().st_size
    bad = flipped(bag, tmp_path / "bad.mcap", size - 200)  # in the summary section
    with pytest.warns(UserWarning, match="summary section unreadable"):
        d = read_run(bad)
    assert d.message_count == read_run(bag).message_count
    assert d.metadata["pneu.run"]["seed"] == "3"


def test_a_damaged_message_index_costs_nothing(bag, tmp_path):
    start, length, _ = chunks_of(bag)[1]
    bad = flipped(bag, tmp_path / "bad.mcap", start + length + 20)  # its first message index
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = read_run(bad)
    whole = read_run(bag)
    assert d.message_count == whole.message_count
    np.testing.assert_array_equal(d[P1]["fluid_pressure"], whole[P1]["fluid_pressure"])


@pytest.mark.parametrize("whole_indexes", [0, 1, 3])
def test_a_cut_in_the_message_indexes_after_a_chunk_keeps_that_whole_chunk(
    bag, tmp_path, whole_indexes
):
    """``ros2 bag record`` SIGKILLed: the file ends inside the message index records that
    follow its last complete chunk (after ``whole_indexes`` of them). That chunk is read
    whole (by walking its CRC-checked records), not only the channels whose index records
    were complete."""
    chunks = chunks_of(bag)
    start, length, _ = chunks[2]
    data = bag.read_bytes()
    end = start + length
    for _ in range(whole_indexes):  # op (1) + length (8) + body
        end += 9 + int.from_bytes(data[end + 1 : end + 9], "little")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: end + 12])
    with pytest.warns(UserWarning, match="truncated"):
        d = read_run(cut)
    assert d.message_count == sum(sum(c.values()) for _, _, c in chunks[:3])
    rep = recover(cut, tmp_path / "fixed.mcap")
    assert rep.messages == d.message_count == independent_count(tmp_path / "fixed.mcap")


@pytest.mark.parametrize("fraction", [0.1, 0.37, 0.62, 0.95])
def test_a_cut_bag_reads_its_complete_chunks_and_recovers(bag, tmp_path, fraction):
    data = bag.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    with pytest.warns(UserWarning, match="truncated"):
        d = read_run(cut)
    n = len(d[P1])
    assert 0 < n < N
    np.testing.assert_array_equal(d[P1]["fluid_pressure"], 1e5 + np.arange(n))
    fixed = tmp_path / "fixed.mcap"
    rep = recover(cut, fixed)
    assert rep.truncated and rep.lost_unknown and rep.messages == d.message_count
    assert independent_count(fixed) == rep.messages


def test_random_flips_never_give_anything_but_data_or_one_line(bag, tmp_path):
    rng = np.random.default_rng(11)
    src = bag.read_bytes()
    outcomes = {"read": 0, "refused": 0, "recovered": 0}
    for i in range(10):
        b = bytearray(src)
        for pos in rng.integers(0, len(b), size=int(rng.choice([1, 3, 20]))):
            b[int(pos)] ^= 1 << int(rng.integers(8))
        p = tmp_path / f"f{i}.mcap"
        p.write_bytes(bytes(b))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                read_run(p)
                outcomes["read"] += 1
            except BagError as err:
                assert "\n" not in str(err) and str(p) in str(err)
                outcomes["refused"] += 1
            out = tmp_path / f"r{i}.mcap"
            try:
                rep = recover(p, out)
            except BagError as err:
                assert "\n" not in str(err)
                assert not out.exists() and not Path(f"{out}.partial").exists()
                continue
        assert independent_count(out, decode=i % 4 == 0) == rep.messages
        outcomes["recovered"] += 1
    assert outcomes["read"] > 0 and outcomes["recovered"] > 0
